"""The outside anchors the project's pipeline is timed and scored against.

`open3d_register`: Open3D's own pipeline, ISS with the paper's parameters, normals, FPFH
at the keypoints, nearest-neighbour correspondences and
`registration_ransac_based_on_correspondence` at 1 m, 99 % confidence, <= 10,000 trials,
with one of two settings of the normal and FPFH searches (`SETTINGS`): 'paper' (normals
and FPFH within 4 m, no neighbour cap, normals towards the sensor: PCL's radius search
and viewpoint rule, docs/method.md §4) or 'tutorial' (Open3D's registration tutorial:
normals within 1 m and at most 30 neighbours, FPFH within 4 m and at most 100: ~4x
faster, less distinctive). Nothing of the project's own pipeline runs there but the
nearest-neighbour matching.

`kiss_matcher_register`: KISS-Matcher (PyPI `kiss-matcher`, the `bench` extra; never a
runtime dependency), refined by Open3D's point-to-plane ICP.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
from scipy import spatial

from ssd_jax.registration import features, keypoints, matching

try:   # the optional anchor (pip install '.[bench]')
  import kiss_matcher
except ImportError:
  kiss_matcher = None

# Metres: KISS-Matcher's voxel size (its examples' for outdoor scans).
KISS_VOXEL = 0.3
KISS_MISSING = "kiss-matcher is not installed (pip install '.[bench]')"


@dataclasses.dataclass(frozen=True)
class SearchSettings:
  """Normal and FPFH neighbourhoods: radii in metres, max_nn None for radius-only; label
  names the setting in tables."""
  normal_radius: float
  normal_max_nn: int | None
  fpfh_radius: float
  fpfh_max_nn: int | None
  orient_to_origin: bool
  label: str


SETTINGS = {
    'paper': SearchSettings(features.FPFH_RADIUS, None, features.FPFH_RADIUS, None, True,
                            "the paper's searches (4 m normals and FPFH, no cap)"),
    'tutorial': SearchSettings(features.NORMAL_RADIUS, features.NORMAL_MAX_NN,
                               features.FPFH_RADIUS, 100, False,
                               "its tutorial's searches (FPFH <= 100 neighbours)"),
}


def _search(o3d, radius: float, max_nn: int | None):
  if max_nn is None:
    return o3d.geometry.KDTreeSearchParamRadius(radius)
  return o3d.geometry.KDTreeSearchParamHybrid(radius=radius, max_nn=max_nn)


def open3d_register(points1: np.ndarray, points2: np.ndarray, seed: int = 0,
                    settings: str = 'paper', iss: tuple[np.ndarray, np.ndarray] | None = None
                    ) -> tuple[np.ndarray, dict, dict]:
  """The plain Open3D pipeline on two clouds [N, 3] metres with the searches of
  `SETTINGS[settings]`; `iss`: each cloud's ISS keypoint indices where already found
  (`keypoints.iss`: the same Open3D call, mapped to indices as here) -> (T_12 [4, 4]
  mapping cloud 2 into cloud 1's frame,
  {stage: seconds} for features (both clouds), matching, ransac, {'matches': K1,
  'inliers': RANSAC's correspondence set size, 'fitness', 'inlier_rmse'} as Open3D's
  `RegistrationResult` gives them)."""
  if settings not in SETTINGS:
    raise ValueError(f'settings must be one of {sorted(SETTINGS)}, got {settings!r}')
  search = SETTINGS[settings]
  import open3d as o3d  # pylint: disable=g-import-not-at-top
  reg = o3d.pipelines.registration
  t0 = time.perf_counter()
  feats = []
  for n, points in enumerate((points1, points2)):
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, np.float64)))
    if iss is None:
      found = o3d.geometry.keypoint.compute_iss_keypoints(pcd, **keypoints.ISS_PARAMS)
      # Open3D gives keypoint coordinates; FPFH at their indices comes in ascending order.
      _, idx = spatial.cKDTree(np.asarray(pcd.points)).query(np.asarray(found.points))
      idx = np.unique(idx)
    else:
      idx = np.asarray(iss[n], np.int64)
    pcd.estimate_normals(_search(o3d, search.normal_radius, search.normal_max_nn))
    if search.orient_to_origin:
      pcd.orient_normals_towards_camera_location(np.zeros(3))
    fpfh = reg.compute_fpfh_feature(pcd, _search(o3d, search.fpfh_radius, search.fpfh_max_nn),
                                    [int(i) for i in idx])
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
  stats = {'matches': len(nn), 'inliers': len(result.correspondence_set),
           'fitness': float(result.fitness), 'inlier_rmse': float(result.inlier_rmse)}
  return (np.asarray(result.transformation),
          {'features': t1 - t0, 'matching': t2 - t1, 'ransac': t3 - t2}, stats)


def kiss_matcher_register(points1: np.ndarray, points2: np.ndarray,
                          voxel: float = KISS_VOXEL) -> np.ndarray:
  """T_12 [4, 4] by KISS-Matcher (cloud 2 [M, 3] onto cloud 1 [N, 3], metres) at its
  defaults with `voxel`, refined by Open3D's point-to-plane ICP (1 m, then 0.5 m; normals
  within 1 m, <= 30 neighbours). A RuntimeError where kiss-matcher is not installed."""
  if kiss_matcher is None:
    raise RuntimeError(KISS_MISSING)
  import open3d as o3d  # pylint: disable=g-import-not-at-top
  matcher = kiss_matcher.KISSMatcher(kiss_matcher.KISSMatcherConfig(voxel))
  solution = matcher.estimate(np.asarray(points2, np.float32), np.asarray(points1, np.float32))
  t = np.eye(4)
  t[:3, :3], t[:3, 3] = np.asarray(solution.rotation), np.asarray(solution.translation)
  reg = o3d.pipelines.registration
  target = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points1))
  target.estimate_normals(_search(o3d, 1.0, 30))
  source = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points2))
  for distance in (1.0, 0.5):
    t = np.asarray(reg.registration_icp(source, target, distance, t,
                                        reg.TransformationEstimationPointToPlane()).transformation)
  return t
