"""Keypoint detectors (host side). Each returns sorted indices into the cloud."""

from __future__ import annotations

import numpy as np
from scipy import spatial

# docs/method.md §4: the parameters of the paper's ISS keypoints.
ISS_PARAMS = dict(salient_radius=1.0, non_max_radius=0.5, gamma_21=0.975, gamma_32=0.975,
                  min_neighbors=7)


def iss(points: np.ndarray, **overrides) -> np.ndarray:
  """Intrinsic Shape Signature keypoints (Open3D) of points [N, 3] metres -> indices [K].

  Open3D returns keypoint coordinates in a thread-dependent order; they are mapped
  back to indices and sorted, so the result is deterministic.
  """
  import open3d as o3d  # pylint: disable=g-import-not-at-top
  params = {**ISS_PARAMS, **overrides}
  pts = np.asarray(points, np.float64)
  kp = o3d.geometry.keypoint.compute_iss_keypoints(
      o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts)), **params)
  kp = np.asarray(kp.points)
  if len(kp) == 0:
    return np.zeros(0, np.int64)
  _, idx = spatial.cKDTree(pts).query(kp)
  return np.unique(idx)


def random_keypoints(rng: np.random.Generator, num_points: int, k: int) -> np.ndarray:
  """k distinct random indices (all when fewer), sorted."""
  return np.sort(rng.choice(num_points, min(k, num_points), replace=False))
