"""Hypothesis verification: which of RANSAC's candidate poses the clouds themselves agree
with.

RANSAC ranks a pose by how many putative correspondences it explains. Where the matches
are few and the scene repeats (a straight street of like objects, two scans tens of
metres apart), a wrong pose can explain as many as the right one, and the right one is
often among the runners-up (`ransac.distinct_best`). Each candidate is refined by
point-to-plane ICP and scored by the share of cloud 2 it lays within `FIT_DISTANCE` of
cloud 1: the dense geometry, not the sparse matches, picks the pose. The same check
that the verification step of a classic registration pipeline makes.
"""

from __future__ import annotations

import numpy as np

# Metres: a cloud-2 point this close to cloud 1 after a candidate's ICP counts as fitting
# (1.5 voxels of the 0.2 m grid: the two grids' offset and the sensors' noise).
FIT_DISTANCE = 0.3
# Cloud-2 points scored and aligned per candidate: an even stride over the cloud.
SOURCE_POINTS = 5000
# ICP of each candidate: correspondences within these distances (metres), in turn.
ICP_DISTANCES = (1.0, 0.5)
ICP_ITERATIONS = 30


def open3d_clouds(target: np.ndarray, source: np.ndarray):
  """Open3D clouds for point-to-plane ICP: target [N1, 3] with normals within 1 m /
  30 neighbours, source [N2, 3] (metres, float64)."""
  import open3d as o3d  # pylint: disable=g-import-not-at-top  (as every Open3D user here)
  cloud = lambda p: o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(p, np.float64)))
  target = cloud(target)
  target.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=1.0, max_nn=30))
  return target, cloud(source)


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


def verify(points1: np.ndarray, points2: np.ndarray, candidates: np.ndarray
           ) -> tuple[int, np.ndarray, np.ndarray]:
  """Candidate poses T_12 [k, 4, 4] of cloud 2 [N2, 3] in cloud 1 [N1, 3] (metres, near
  the origin) -> (index of the best, each candidate refined by ICP [k, 4, 4], their
  fitness [k]: share of cloud 2 within FIT_DISTANCE of cloud 1). Ties keep the earlier
  candidate (RANSAC's order). Open3D's ICP sums over its threads, so the poses repeat to
  rounding, not bit for bit."""
  import open3d as o3d  # pylint: disable=g-import-not-at-top
  target, source = open3d_clouds(points1,
                                 np.asarray(points2)[::max(1, len(points2) // SOURCE_POINTS)])
  refined = np.stack([point_to_plane_icp(target, source, t)[0] for t in candidates])
  fitness = np.array([o3d.pipelines.registration.evaluate_registration(
      source, target, FIT_DISTANCE, t).fitness for t in refined])
  return int(np.argmax(fitness)), refined, fitness
