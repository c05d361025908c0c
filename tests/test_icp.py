"""Point-to-plane ICP on a surface made once: the same poses as Open3D's."""

import numpy as np
import pytest

from ssd_jax import geometry
from ssd_jax.data import io, preprocess
from ssd_jax.registration import icp
from tests.conftest import shared_path


def _scan() -> np.ndarray:
  return io.read_cloud(shared_path('example', 'kitti_00_001554.bin')).astype(np.float64)


def test_least_axis_is_the_eigenvector_of_the_smallest_eigenvalue():
  rng = np.random.default_rng(0)
  a = rng.normal(size=(500, 3, 3))
  cov = a @ np.swapaxes(a, 1, 2)
  cov[:100, 2] *= 1e-3          # nearly planar neighbourhoods, as on a wall
  cov[:100, :, 2] *= 1e-3
  _, vectors = np.linalg.eigh(cov)
  dot = np.abs(np.sum(icp.least_axis(cov) * vectors[:, :, 0], 1))
  np.testing.assert_allclose(dot, 1.0, atol=1e-9)
  np.testing.assert_array_equal(icp.least_axis(np.eye(3)[None]), [[0.0, 0.0, 1.0]])
  assert icp.least_axis(np.zeros((0, 3, 3))).shape == (0, 3)


def test_isolated_points_get_the_default_normal():
  """Points more than a normal radius from any other (a sparse tile's far returns) have no
  plane: (0, 0, 1), as with too few neighbours, also when every queried point is one."""
  points = np.array([[0.0, 0, 0], [5, 0, 0], [10, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0.1, 0.1, 0.01]])
  surface = icp.surface(points)
  np.testing.assert_array_equal(surface.normals_at(np.array([1, 2])), [[0, 0, 1.0]] * 2)
  assert abs(surface.normals_at(np.array([0]))[0, 2]) > 0.99


@pytest.mark.real_data
def test_normals_and_icp_match_open3d_on_a_real_scan():
  """Normals within 1 m / 30 neighbours agree with Open3D's (up to sign), and ICP from a
  pose 1 m and 3 degrees off lands where Open3D's registration_icp lands, with its
  fitness."""
  import open3d as o3d  # pylint: disable=g-import-not-at-top
  points = _scan()
  surface = icp.surface(points)
  surface_normals = surface.normals_at(np.arange(len(points)))
  reference = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
  reference.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=1.0, max_nn=30))
  dot = np.abs(np.sum(np.asarray(reference.normals) * surface_normals, 1))
  assert np.percentile(dot, 1) > 0.999
  t_true = geometry.make_transform(geometry.rotation_z(np.radians(20.0)), np.array([3.0, -1.0, 0.1]))
  source = ((points[::6] - t_true[:3, 3]) @ t_true[:3, :3]
            + np.random.default_rng(0).normal(0, 0.02, points[::6].shape))
  start = t_true @ geometry.make_transform(geometry.rotation_z(np.radians(3.0)),
                                           np.array([0.8, -0.6, 0.0]))
  t, fitness = icp.point_to_plane(surface, source, start, (1.0, 0.5))
  reg = o3d.pipelines.registration
  target = o3d.geometry.PointCloud(reference)
  src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(source))
  expected = start
  for distance in (1.0, 0.5):
    result = reg.registration_icp(src, target, distance, expected,
                                  reg.TransformationEstimationPointToPlane(),
                                  reg.ICPConvergenceCriteria(max_iteration=30))
    expected = np.asarray(result.transformation)
  np.testing.assert_allclose(t, expected, atol=1e-4)
  assert fitness == pytest.approx(result.fitness, abs=1e-3)
  assert np.linalg.norm(t[:3, 3] - t_true[:3, 3]) < 0.05


def test_occupied_voxels_counts_what_voxel_downsample_returns():
  rng = np.random.default_rng(1)
  for points in (rng.uniform(-30, 30, (20_000, 3)), rng.normal(500.0, 3.0, (5_000, 3))):
    for voxel in (0.2, 1.0):
      assert preprocess.occupied_voxels(points, voxel) == len(
          preprocess.voxel_downsample(points, voxel))


def test_a_robust_icp_is_not_dragged_by_what_one_scan_alone_saw():
  """An L of two walls on a floor; cloud 2 also sees a hedge 0.6 m before one wall, which
  cloud 1 never saw. From 0.3 m and 1 degree off, the plain ICP pairs the hedge with the
  wall and ends 0.4 m off; the robust one ends on the pose, where Open3D's point-to-plane
  ICP with its Geman-McClure loss (k = the scale squared) ends."""
  import open3d as o3d  # pylint: disable=g-import-not-at-top
  rng = np.random.default_rng(0)
  walls = lambda n: np.concatenate([
      np.c_[rng.uniform(0, 20, (2 * n, 2)), np.zeros(2 * n)],
      np.c_[rng.uniform(0, 20, n), np.zeros(n), rng.uniform(0, 4, n)],
      np.c_[np.zeros(n), rng.uniform(0, 20, n), rng.uniform(0, 4, n)]])
  hedge = np.c_[rng.uniform(0, 20, 4000), np.full(4000, 0.6), rng.uniform(0, 3, 4000)]
  target = walls(3000)
  t_true = geometry.make_transform(geometry.rotation_z(np.radians(10.0)), np.array([1.0, 2.0, 0.0]))
  source = (np.concatenate([walls(1500), hedge]) - t_true[:3, 3]) @ t_true[:3, :3]
  start = t_true @ geometry.make_transform(geometry.rotation_z(np.radians(1.0)),
                                           np.array([0.2, -0.2, 0.0]))
  surface = icp.surface(target)
  off = lambda t: np.linalg.norm(t[:3, 3] - t_true[:3, 3])
  plain, _ = icp.point_to_plane(surface, source, start, (1.0, 0.5))
  robust, _ = icp.point_to_plane(surface, source, start, (1.0, 0.5), robust=True)
  assert off(plain) > 0.3 and off(robust) < 0.03, (off(plain), off(robust))
  reg = o3d.pipelines.registration
  tgt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(target))
  tgt.normals = o3d.utility.Vector3dVector(surface.normals_at(np.arange(len(target))))
  src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(source))
  expected = start
  for distance in (1.0, 0.5):
    loss = reg.GMLoss(k=(icp.ROBUST_SCALE * distance) ** 2)
    expected = np.asarray(reg.registration_icp(
        src, tgt, distance, expected, reg.TransformationEstimationPointToPlane(loss),
        reg.ICPConvergenceCriteria(max_iteration=30)).transformation)
  np.testing.assert_allclose(robust, expected, atol=1e-3)
