"""What the scans fix of a pose: Open3D's information matrix, and the free direction of a
corridor, a tunnel and a highway between barriers (synthetic scans with exact poses)."""

import numpy as np
import pytest

from ssd_jax import geometry, pretrained
from ssd_jax.data import io
from ssd_jax.registration import icp, metrics, pipeline, uncertainty, verification
from ssd_jax.registration import cloud_features
from ssd_jax.synthetic import degenerate
from tests.conftest import shared_path


def _real_pair():
  scan = io.read_cloud(shared_path('kitti_object_velodyne', '000000.bin')).astype(np.float64)
  t = geometry.make_transform(geometry.rotation_z(np.radians(30.0)), np.array([2.0, 1.0, 0.1]))
  return scan[::2], (scan[1::2] - t[:3, 3]) @ t[:3, :3], t


@pytest.mark.real_data
def test_information_matrix_is_open3ds():
  """Open3D's get_information_matrix_from_point_clouds, also about another origin."""
  import open3d as o3d  # pylint: disable=g-import-not-at-top  (the reference only)
  target, source, t = _real_pair()
  cloud = lambda p: o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p))
  expected = o3d.pipelines.registration.get_information_matrix_from_point_clouds(
      cloud(source), cloud(target), uncertainty.DISTANCE, t)
  assessed = uncertainty.assess(icp.surface(target), source, t)
  np.testing.assert_allclose(assessed.information, expected, rtol=0, atol=1e-5 * np.abs(expected).max())
  # The same clouds 100 m away, assessed about cloud 1's frame origin there.
  offset = np.array([100.0, -50.0, 3.0])
  moved = geometry.make_transform(np.eye(3), offset)
  shifted = uncertainty.assess(icp.surface(target - offset), source - offset,
                               np.linalg.inv(moved) @ t @ moved, origin=-offset)
  np.testing.assert_allclose(shifted.information, expected, rtol=0,
                             atol=1e-5 * np.abs(expected).max())
  # A real street fixes every direction, well above the bound.
  held = assessed.translation_constraint[0]
  assert not assessed.free and held > 5 * uncertainty.MIN_CONSTRAINT
  assert assessed.correspondences > 10_000
  # Under a stricter bound than what holds its least held shift, that shift is named.
  assert assessed.free_under(0.99 * held) == ''
  stricter = assessed.free_under(1.01 * held)
  assert stricter.startswith('translation along (') and (
      f'{held:.2g} per correspondence, under {1.01 * held:g}') in stricter, stricter


@pytest.mark.parametrize('kind', degenerate.KINDS)
def test_a_shift_along_a_corridor_tunnel_or_highway_is_free(kind):
  """Scans 5 m apart along the scene, registered by the defaults: a wrong shift along it
  with a fitness near 1, and the assessment names translation along x as free."""
  cloud1, cloud2, t_true = degenerate.scan_pair(kind)
  np.testing.assert_allclose(t_true[:3, 3], [5.0, 0.0, 0.0])
  reg, _, _ = pipeline.register(target=cloud1, source=cloud2, model=pretrained.load('ours'))
  assert metrics.registration_errors(t_true, reg.transform)['rte'] > 1.0
  assert reg.verified_fitness.max() > 0.9
  u = reg.uncertainty
  assert u.translation_constraint[0] < uncertainty.MIN_CONSTRAINT, u.translation_constraint
  assert u.free.startswith('translation along (1.00, ') and 'not fixed' in u.free, u.free
  assert f'under {uncertainty.MIN_CONSTRAINT:g}' in u.free, u.free
  assert abs(u.translation_directions[0][0]) > 0.99
  # The truth is no better fixed: the same direction is free there.
  grid1, _ = cloud_features.to_grid(cloud1, 0.2)
  grid2, _ = cloud_features.to_grid(cloud2, 0.2)
  at_truth = uncertainty.assess(verification.target(grid1), verification.source(grid2).points,
                                t_true)
  assert at_truth.translation_constraint[0] < uncertainty.MIN_CONSTRAINT


def test_directions_are_named_by_their_larger_part():
  assert (uncertainty.describe_direction(np.array([0, 0, 0, -0.99, -0.1, 0.0]))
          == 'translation along (0.99, 0.10, 0.00)')
  assert (uncertainty.describe_direction(np.array([0.1, 0, -0.9, 0.1, 0, 0]))
          == 'rotation about (-0.11, 0.00, 0.99)')
