"""Scenes whose geometry leaves a pose free, scanned with exact poses: a straight corridor,
a tunnel and a highway between barriers.

Two scans taken a few metres apart along such a scene look the same at every shift along
it: point-to-plane ICP and any descriptor see walls, a vault or barriers whose normals all
point across the way. Registration must say so instead of returning a pose
(`registration.uncertainty`). Each scene is a few long planes (or a vault of strips)
along x, scanned by `lidar.scan` (Open3D ray casting) from sensors on the x axis.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ssd_jax import geometry
from ssd_jax.synthetic import lidar
from ssd_jax.synthetic.scene import Label

KINDS = ('corridor', 'tunnel', 'highway')
LENGTH = 400.0          # metres of scene along x, centred on the origin
SENSOR_HEIGHT = 1.73    # metres above the floor (KITTI's Velodyne)


@dataclasses.dataclass(frozen=True)
class Meshes:
  """What `lidar.Raycaster` reads of a scene: triangles per label."""
  vertices: dict
  triangles: dict


def _quads(corners: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
  """Quads [4, 3] (corners in order) -> vertices [4Q, 3] float32, triangles [2Q, 3]."""
  vertices = np.concatenate(corners).astype(np.float32)
  base = 4 * np.arange(len(corners))[:, None]
  triangles = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]]).astype(np.uint32)
  return vertices, triangles


def _strip(y0: float, z0: float, y1: float, z1: float) -> np.ndarray:
  """The quad along x over the whole scene between (y0, z0) and (y1, z1)."""
  h = LENGTH / 2
  return np.array([[-h, y0, z0], [h, y0, z0], [h, y1, z1], [-h, y1, z1]])


def meshes(kind: str) -> Meshes:
  """The scene `kind` (one of KINDS), its floor at z = 0:
    corridor: a floor 6 m wide between two 3 m walls;
    tunnel: a road 9 m wide under a half-round vault of 5 m radius (24 strips);
    highway: a 40 m wide road between two 1 m concrete barriers, flat ground beyond."""
  if kind == 'corridor':
    quads = [_strip(-3, 0, 3, 0), _strip(-3, 0, -3, 3), _strip(3, 0, 3, 3)]
  elif kind == 'tunnel':
    angles = np.linspace(0.0, np.pi, 25)
    arc = np.stack([5.0 * np.cos(angles), 1.5 + 5.0 * np.sin(angles)], 1)
    quads = [_strip(-5, 0, 5, 0), _strip(-5, 0, -5, 1.5), _strip(5, 0, 5, 1.5)]
    quads += [_strip(*a, *b) for a, b in zip(arc[:-1], arc[1:])]
  elif kind == 'highway':
    quads = [_strip(-60, 0, 60, 0), _strip(-20, 0, -20, 1), _strip(-20.3, 1, -20, 1),
             _strip(20, 0, 20, 1), _strip(20, 1, 20.3, 1)]
  else:
    raise ValueError(f'kind must be one of {KINDS}, got {kind!r}')
  vertices, triangles = _quads(quads)
  return Meshes({Label.BUILDING: vertices}, {Label.BUILDING: triangles})


def scan_pair(kind: str, shift: float = 5.0, crop: float = 35.0, yaw_deg: float = 0.0,
              seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
  """Two scans of the scene `kind` by a 64-beam unit (`lidar.LidarModel()`): cloud 1 from
  the origin, cloud 2 from `shift` metres further along x, turned by `yaw_deg` about z,
  each cropped to `crop` metres around its sensor, in its sensor's frame.
  -> (cloud 1 [N1, 3], cloud 2 [N2, 3] float64 metres, T_12 [4, 4] exact)."""
  raycaster = lidar.Raycaster(meshes(kind))
  model = lidar.LidarModel()
  rng = np.random.default_rng(seed)
  poses = [geometry.make_transform(np.eye(3), np.array([0.0, 0.0, SENSOR_HEIGHT])),
           geometry.make_transform(geometry.rotation_z(np.radians(yaw_deg)),
                                   np.array([shift, 0.0, SENSOR_HEIGHT]))]
  clouds = []
  for pose in poses:
    points = lidar.scan(raycaster, pose, model, rng)[0].astype(np.float64)
    clouds.append(points[np.linalg.norm(points[:, :2], axis=1) < crop])
  return clouds[0], clouds[1], np.linalg.inv(poses[0]) @ poses[1]
