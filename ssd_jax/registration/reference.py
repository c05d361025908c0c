"""Open3D's own registration pipeline, as its tutorial writes it: the outside reference
the project's pipeline is timed and scored against.

Open3D's ISS with the paper's parameters, normals within 1 m (30 neighbours), FPFH
within 4 m and at most 100 neighbours, nearest-neighbour correspondences, and
`registration_ransac_based_on_correspondence` at 1 m, 99 % confidence, <= 10,000 trials.
Nothing of the project's own pipeline runs here but the nearest-neighbour matching.
"""

from __future__ import annotations

import time

import numpy as np
from scipy import spatial

from ssd_jax.registration import features, keypoints, matching

FPFH_MAX_NN = 100   # the tutorial's cap


def open3d_register(points1: np.ndarray, points2: np.ndarray, seed: int = 0
                    ) -> tuple[np.ndarray, dict]:
  """The plain Open3D pipeline on two clouds [N, 3] metres -> (T_12 [4, 4] mapping cloud 2
  into cloud 1's frame, {stage: seconds} for features (both clouds), matching, ransac)."""
  import open3d as o3d  # pylint: disable=g-import-not-at-top
  reg = o3d.pipelines.registration
  t0 = time.perf_counter()
  feats = []
  for points in (points1, points2):
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, np.float64)))
    iss = o3d.geometry.keypoint.compute_iss_keypoints(pcd, **keypoints.ISS_PARAMS)
    # Open3D gives keypoint coordinates; FPFH at their indices comes in ascending order.
    _, idx = spatial.cKDTree(np.asarray(pcd.points)).query(np.asarray(iss.points))
    idx = np.unique(idx)
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(
        radius=features.NORMAL_RADIUS, max_nn=features.NORMAL_MAX_NN))
    fpfh = reg.compute_fpfh_feature(pcd, o3d.geometry.KDTreeSearchParamHybrid(
        radius=features.FPFH_RADIUS, max_nn=FPFH_MAX_NN), [int(i) for i in idx])
    feats.append((np.asarray(pcd.points)[idx], np.asarray(fpfh.data).T))
  t1 = time.perf_counter()
  if min(len(feats[0][0]), len(feats[1][0])) < 3:
    raise ValueError(f'too few ISS keypoints to register ({len(feats[0][0])} and '
                     f'{len(feats[1][0])}; at least 3 each)')
  nn = matching.nearest_neighbour_matches(feats[0][1], feats[1][1])
  corres = o3d.utility.Vector2iVector(np.stack([nn, np.arange(len(nn))], 1).astype(np.int32))
  t2 = time.perf_counter()
  o3d.utility.random.seed(seed)
  cloud = lambda p: o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p))
  result = reg.registration_ransac_based_on_correspondence(
      cloud(feats[1][0]), cloud(feats[0][0]), corres, 1.0,
      reg.TransformationEstimationPointToPoint(False), 3, [],
      reg.RANSACConvergenceCriteria(10_000, 0.99))
  t3 = time.perf_counter()
  return np.asarray(result.transformation), {'features': t1 - t0, 'matching': t2 - t1,
                                             'ransac': t3 - t2}
