"""Scan processing as 3DFeat-Net's test sets were made: voxel grid, normals, fixed size.

Host-side Open3D; every function is deterministic for the same input.
"""

from __future__ import annotations

import numpy as np


def even_stride(n: int, count: int) -> int:
  """The step of an even stride over n items that keeps at most `count` of them (1: all),
  the work budget of the stages that would otherwise grow with a map tile's size."""
  return max(1, -(-n // count))


def _o3d_cloud(points: np.ndarray):
  import open3d as o3d  # pylint: disable=g-import-not-at-top
  return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, np.float64)))


def voxel_downsample(points: np.ndarray, voxel_size: float, dtype=np.float32) -> np.ndarray:
  """Centroid of the points in each occupied voxel (computed in float64). [N, 3] -> [M, 3]
  `dtype` metres."""
  if voxel_size <= 0:
    return np.asarray(points, dtype)
  down = _o3d_cloud(points).voxel_down_sample(voxel_size)
  return np.asarray(down.points, dtype)


def occupied_voxels(points: np.ndarray, voxel_size: float) -> int:
  """How many points [N, 3] `voxel_downsample` returns (its voxels: Open3D's, from the
  cloud's lower bound less half a voxel), counted in numpy without Open3D."""
  points = np.asarray(points, np.float64)
  if not len(points):
    return 0
  cell = np.floor((points - (points.min(0) - voxel_size / 2)) / voxel_size).astype(np.int64)
  cell -= cell.min(0)
  span = cell.max(0) + 1
  key = (cell[:, 0] * span[1] + cell[:, 1]) * span[2] + cell[:, 2]
  return int(len(np.unique(key)))


def process_scan(points: np.ndarray, voxel_size: float = 0.2,
                 normal_radius: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
  """3DFeat-Net's test-set processing: voxel grid, then normals facing the sensor at
  the origin. [N, 3] -> points [M, 3], normals [M, 3]."""
  points = voxel_downsample(points, voxel_size)
  return points, estimate_normals(points, normal_radius)


def estimate_normals(points: np.ndarray, radius: float = 1.0, max_nn: int = 30,
                     viewpoint=(0.0, 0.0, 0.0)) -> np.ndarray:
  """Unit normals [N, 3] from PCA of up to `max_nn` neighbours within `radius`
  metres, flipped to face `viewpoint` (the sensor)."""
  import open3d as o3d  # pylint: disable=g-import-not-at-top
  pcd = _o3d_cloud(points)
  pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=radius, max_nn=max_nn))
  pcd.orient_normals_towards_camera_location(np.asarray(viewpoint, np.float64))
  return np.asarray(pcd.normals, np.float32)

