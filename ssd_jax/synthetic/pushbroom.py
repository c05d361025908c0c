"""A 2D push-broom LiDAR driven along a street, its scan lines accumulated into a map.

Oxford RobotCar's test models (3DFeat-Net's processing) are not one spinning scan: a
SICK LMS-151 sweeps a vertical plane as the car drives, and its lines are accumulated
with the vehicle's INS poses over ~60 m. The density is that of the lines, dense
across the street and thin along it, with no rings and no sensor-centred occlusion.
This module simulates that sensor with the same ray caster as `lidar`: one fan of
rays per pose, its returns placed in the world with the pose the vehicle *reports*
(the true pose plus a small error), so accumulated maps carry the blur of real ones.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ssd_jax.synthetic import trajectory
from ssd_jax.synthetic.lidar import Raycaster, check_sensor_fields
from ssd_jax.synthetic.scene import Label


@dataclasses.dataclass(frozen=True)
class PushbroomModel:
  """An LMS-151-like line scanner; angles in degrees, distances in metres.

  The scan plane is the sensor's y-z plane turned by `tilt` about its y axis (0: across
  the driving direction x); angle 0 points straight down and the `fov` is centred
  there, so the blind sector points at the sky.
  """
  fov: float = 270.0
  angular_step: float = 0.5
  min_range: float = 0.5
  max_range: float = 50.0
  range_noise: float = 0.012
  dropout: float = 0.02
  glass_dropout: float = 0.8
  tilt: float = 0.0

  def __post_init__(self):
    if not 0 < self.fov <= 360 or not 0 < self.angular_step <= self.fov:
      raise ValueError(f'need 0 < angular_step <= fov <= 360 degrees, got fov={self.fov}, '
                       f'angular_step={self.angular_step}')
    check_sensor_fields(self, ('dropout', 'glass_dropout'), ('range_noise',))

  def angles(self) -> np.ndarray:
    """Beam angles [A] radians from straight down, towards +y first."""
    half = self.fov / 2
    return np.radians(np.arange(-half, half + 1e-9, self.angular_step))

  def directions(self) -> np.ndarray:
    """Unit ray directions [A, 3] in the sensor frame (x forward, y left, z up)."""
    a = self.angles()
    d = np.stack([np.zeros_like(a), np.sin(a), -np.cos(a)], -1)
    c, s = np.cos(np.radians(self.tilt)), np.sin(np.radians(self.tilt))
    return d @ np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]).T


def accumulate(raycaster: Raycaster, true_poses: np.ndarray, model: PushbroomModel,
               rng: np.random.Generator, reported_poses: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
  """Cast one line per pose and place its returns in the world.

  true_poses [L, 4, 4] T_world_sensor where each line was taken; reported_poses
  [L, 4, 4] the poses the vehicle believed (default: the true ones), which place the
  returns. -> (points [M, 3] float64 world metres, labels [M] int8, line index [M]).
  """
  reported = true_poses if reported_poses is None else reported_poses
  dirs = model.directions()
  pts, labels, lines = [], [], []
  for k, (pose, placed) in enumerate(zip(true_poses, reported)):
    dirs_w = dirs @ pose[:3, :3].T
    t, label, _ = raycaster.cast(np.broadcast_to(pose[:3, 3], dirs_w.shape), dirs_w)
    keep = (label >= 0) & (t >= model.min_range) & (t <= model.max_range)
    p_drop = np.where(label == Label.GLASS, model.glass_dropout, model.dropout)
    keep &= rng.uniform(size=len(t)) >= p_drop
    r = t[keep] + model.range_noise * rng.standard_normal(int(keep.sum()))
    local = dirs[keep] * r[:, None]
    pts.append(local @ placed[:3, :3].T + placed[:3, 3])
    labels.append(label[keep].astype(np.int8))
    lines.append(np.full(int(keep.sum()), k, np.int32))
  return np.concatenate(pts), np.concatenate(labels), np.concatenate(lines)


def line_poses(scene, rng: np.random.Generator, line_spacing: float, mount_height: float,
               drift_m: float = 0.02, drift_deg: float = 0.05
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
  """The poses of every scan line of a drive down the street and back in the other lane
  (a second traversal of each place): one every `line_spacing` metres, following the
  lane smoothly (a car does not yaw from one 20 ms line to the next).

  -> (true [L, 4, 4], reported [L, 4, 4] T_world_sensor, leg [L] int: 0 down the
  street, 1 back): the reported poses drift from the true ones by a random walk that
  reaches about `drift_m` metres and `drift_deg` degrees of yaw per 60 m, as an INS
  between corrections does.
  """
  true = trajectory.drive(scene, rng, line_spacing, mount_height, weave=0.0,
                          yaw_noise_deg=0.0, tilt_noise_deg=0.0)
  steps = max(1.0, 60.0 / line_spacing)
  walk = lambda scale, shape: np.cumsum(rng.standard_normal(shape), 0) * scale / np.sqrt(steps)
  reported = true.copy()
  reported[:, :3, 3] += walk(drift_m, (len(true), 3))
  yaw = walk(np.radians(drift_deg), len(true))
  reported[:, :3, :3] = trajectory.rotation_zyx(yaw, np.zeros_like(yaw),
                                                np.zeros_like(yaw)) @ true[:, :3, :3]
  leg = (true[:, :3, 0] @ true[0, :3, 0] < 0).astype(np.int64)   # heading turned around
  return true, reported, leg


def submap(points: np.ndarray, lines: np.ndarray, line_xyz: np.ndarray, leg: np.ndarray,
           centre: int, radius: float) -> np.ndarray:
  """The points [M, 3] of the lines of `centre`'s traversal (`leg`) whose pose lies
  within `radius` metres (in the plane) of line `centre`'s: ~2 radius metres of one
  pass down the street."""
  near = ((np.linalg.norm(line_xyz[:, :2] - line_xyz[centre, :2], axis=1) <= radius)
          & (leg == leg[centre]))
  return points[near[lines]]
