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

from ssd_jax.synthetic.lidar import Raycaster
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
    if not 0 <= self.min_range < self.max_range:
      raise ValueError(f'need 0 <= min_range < max_range, got {self.min_range}, {self.max_range}')
    for name in ('dropout', 'glass_dropout'):
      if not 0 <= getattr(self, name) < 1:
        raise ValueError(f'{name} must be in [0, 1), got {getattr(self, name)}')
    if self.range_noise < 0:
      raise ValueError(f'range_noise must be >= 0, got {self.range_noise}')

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
