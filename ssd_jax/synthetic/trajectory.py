"""Sensor poses along a drive through a scene.

The car drives down the street in the right-hand lane and comes back in the
other lane, so the return leg revisits every place in the opposite direction
(a loop closure, as KITTI's pairs often are). Poses follow the ground: height =
ground + mount height; pitch and roll follow the road's grade and cross slope,
plus small noise for suspension; yaw follows the lane with a little weaving.
"""

from __future__ import annotations

import numpy as np

from ssd_jax.synthetic.scene import Scene


def rotation_zyx(yaw: np.ndarray, pitch: np.ndarray, roll: np.ndarray) -> np.ndarray:
  """R = Rz(yaw) Ry(pitch) Rx(roll), radians [...] -> [..., 3, 3]."""
  cy, sy, cp, sp, cr, sr = (np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch),
                            np.cos(roll), np.sin(roll))
  return np.stack([
      np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], -1),
      np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], -1),
      np.stack([-sp, cp * sr, cp * cr], -1)], -2)


MARGIN = 15.0   # metres a drive keeps from each end of the street


def drive(scene: Scene, rng: np.random.Generator, spacing: float, mount_height: float,
          spacing_jitter: float = 0.0, margin: float = MARGIN, return_leg: bool = True,
          weave: float = 0.3,
          yaw_noise_deg: float = 1.0, tilt_noise_deg: float = 0.3) -> np.ndarray:
  """Sensor poses T_world_sensor [P, 4, 4], one every `spacing` metres of travel, each
  moved along the lane by up to ±spacing_jitter × spacing."""
  st = scene.style
  lane = max(1.0, (st.road_half_width - 2.2) / 2)
  out_s = np.arange(margin, st.length - margin, spacing)
  legs = [(out_s, -lane, 0.0)]
  if return_leg:
    back_s = np.arange(st.length - margin - rng.uniform(0, spacing), margin, -spacing)
    legs.append((back_s, lane, np.pi))
  poses = []
  for s, d0, turn in legs:
    s = s + spacing_jitter * spacing * rng.uniform(-1, 1, len(s))
    d = d0 + weave * rng.uniform(-1, 1, len(s))
    direction = -1.0 if turn else 1.0
    eps = 0.5
    grade = (scene.ground_height(s + eps, d) - scene.ground_height(s - eps, d)) / (2 * eps)
    cross = (scene.ground_height(s, d + eps) - scene.ground_height(s, d - eps)) / (2 * eps)
    yaw = scene.centerline.heading_at(s) + turn + np.radians(yaw_noise_deg) * rng.standard_normal(len(s))
    noise = np.radians(tilt_noise_deg) * rng.standard_normal((2, len(s)))
    pitch = -np.arctan(direction * grade) + noise[0]
    roll = np.arctan(direction * cross) + noise[1]
    xy = scene.centerline.to_world(s, d)
    z = scene.ground_height(s, d) + mount_height
    pose = np.tile(np.eye(4), (len(s), 1, 1))
    pose[:, :3, :3] = rotation_zyx(yaw, pitch, roll)
    pose[:, :3, 3] = np.c_[xy, z]
    poses.append(pose)
  return np.concatenate(poses)
