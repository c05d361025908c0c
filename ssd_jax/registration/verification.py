"""Hypothesis verification: which of RANSAC's candidate poses the clouds themselves agree
with.

RANSAC ranks a pose by how many putative correspondences it explains. Where the matches
are few and the scene repeats (a straight street of like objects, two scans tens of
metres apart), a wrong pose can explain as many as the right one, and the right one is
often among the runners-up (`ransac.distinct_best`). Candidates may also come from the
whole scene (`bev.search`). Each is refined by point-to-plane ICP and scored by the share
of cloud 2's structure (what rises from the ground) it lays within `FIT_DISTANCE` of cloud
1: the dense geometry, not the sparse matches, picks the pose. The same check that the
verification step of a classic registration pipeline makes.
"""

from __future__ import annotations

import numpy as np

from ssd_jax.data import preprocess
from ssd_jax.registration import bev

# Metres: a cloud-2 point this close to cloud 1 after a candidate's ICP counts as fitting
# (1.5 voxels of the 0.2 m grid: the two grids' offset and the sensors' noise).
FIT_DISTANCE = 0.3
# Cloud-2 points scored and aligned per candidate: an even stride over the cloud.
SOURCE_POINTS = 5000
# Cloud-1 points ICP aligns to, at most (an even stride over a denser cloud): its normals
# are the verification's largest cost, ~10 s for a map tile's 1.5 M grid points. Every
# cloud of the project's test sets (<= 46,000 points) is used whole.
TARGET_POINTS = 400_000
# What a candidate is scored on: the ground fits every upright pose that keeps it level,
# and covers most of a scan; only what rises from it (walls, poles, cars) tells a pose
# from one shifted along a street ('rising'). A cloud with fewer such points than
# MIN_RISING_POINTS (a bare field) is scored on all of them ('all').
SCORE_ON = 'rising'
MIN_RISING_POINTS = 200
# ICP of each candidate: correspondences within these distances (metres), in turn.
ICP_DISTANCES = (1.0, 0.5)
ICP_ITERATIONS = 30


def _open3d_cloud(points: np.ndarray):
  import open3d as o3d  # pylint: disable=g-import-not-at-top  (as every Open3D user here)
  return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, np.float64)))


def open3d_clouds(target: np.ndarray, source: np.ndarray):
  """Open3D clouds for point-to-plane ICP: target [N1, 3] with normals within 1 m /
  30 neighbours, source [N2, 3] (metres, float64)."""
  import open3d as o3d  # pylint: disable=g-import-not-at-top
  target = _open3d_cloud(target)
  target.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=1.0, max_nn=30))
  return target, _open3d_cloud(source)


def point_to_plane_icp(target, source, transform: np.ndarray, distances=ICP_DISTANCES,
                       iterations: int = ICP_ITERATIONS) -> tuple[np.ndarray, float]:
  """Open3D point-to-plane ICP of `open3d_clouds` from T_12 [4, 4], with correspondences
  within each of `distances` (metres) in turn -> (T_12, share of source points with a
  partner at the last distance)."""
  import open3d as o3d  # pylint: disable=g-import-not-at-top
  reg = o3d.pipelines.registration
  t = np.asarray(transform, np.float64)
  for dist in distances:
    result = reg.registration_icp(source, target, dist, t,
                                  reg.TransformationEstimationPointToPlane(),
                                  reg.ICPConvergenceCriteria(max_iteration=iterations))
    t = np.asarray(result.transformation)
  return t, float(result.fitness)


def _even(points: np.ndarray, count: int) -> np.ndarray:
  return points[::max(1, len(points) // count)]


def verify(points1: np.ndarray, points2: np.ndarray, candidates: np.ndarray,
           score_on: str = SCORE_ON) -> tuple[int, np.ndarray, np.ndarray]:
  """Candidate poses T_12 [k, 4, 4] of cloud 2 [N2, 3] in cloud 1 [N1, 3] (metres, near
  the origin, z up) -> (index of the best, each candidate refined by ICP [k, 4, 4], their
  fitness [k]: the share of cloud 2's points that rise from the ground (`score_on`
  'rising'; 'all': of all its points) within FIT_DISTANCE of cloud 1). Ties keep the
  earlier candidate (RANSAC's order). Open3D's ICP sums over its threads, so the poses
  repeat to rounding, not bit for bit."""
  import open3d as o3d  # pylint: disable=g-import-not-at-top
  if score_on not in ('rising', 'all'):
    raise ValueError(f"score_on must be 'rising' or 'all', got {score_on!r}")
  points2 = np.asarray(points2)
  points1 = np.asarray(points1)
  target, source = open3d_clouds(points1[::preprocess.even_stride(len(points1), TARGET_POINTS)],
                                 _even(points2, SOURCE_POINTS))
  refined = np.stack([point_to_plane_icp(target, source, t)[0] for t in candidates])
  scored = source
  if score_on == 'rising':
    rising = points2[bev.rising_from_ground(points2)]
    if len(rising) >= MIN_RISING_POINTS:
      scored = _open3d_cloud(_even(rising, SOURCE_POINTS))
  fitness = np.array([o3d.pipelines.registration.evaluate_registration(
      scored, target, FIT_DISTANCE, t).fitness for t in refined])
  return int(np.argmax(fitness)), refined, fitness
