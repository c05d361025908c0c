import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ssd_jax import geometry


def test_rotation_z_matches_right_hand_rule():
  r = np.asarray(geometry.rotation_z(jnp.float32(np.pi / 2)))
  np.testing.assert_allclose(np.array([1.0, 0, 0]) @ r.T, [0, 1, 0], atol=1e-6)


def test_random_rotations_are_proper():
  rs = np.asarray(geometry.random_so3(jax.random.key(0), (64,)))
  np.testing.assert_allclose(rs @ np.swapaxes(rs, 1, 2), np.broadcast_to(np.eye(3), rs.shape),
                             atol=1e-5)
  np.testing.assert_allclose(np.linalg.det(rs), 1.0, atol=1e-5)


def test_random_z_angle_is_clipped_and_seeded():
  a = geometry.random_z_angle(jax.random.key(1), (10000,), 0.6, 1.8)
  assert float(jnp.max(jnp.abs(a))) <= 1.8
  assert 0.55 < float(jnp.std(a)) < 0.65
  np.testing.assert_array_equal(a, geometry.random_z_angle(jax.random.key(1), (10000,), 0.6, 1.8))


def test_quaternion_round_trip_including_half_turns():
  rs = geometry.random_so3(jax.random.key(2), (100,))
  half_turn = jnp.diag(jnp.array([1.0, -1.0, -1.0]))  # 180 deg about x: w = 0
  rs = jnp.concatenate([rs, half_turn[None]], 0)
  q = geometry.matrix_to_quaternion(rs)
  np.testing.assert_allclose(geometry.quaternion_to_matrix(q), rs, atol=1e-5)
  np.testing.assert_allclose(geometry.matrix_to_quaternion(half_turn), [0, 1, 0, 0], atol=1e-6)


def test_quaternion_is_scalar_first():
  q = geometry.matrix_to_quaternion(geometry.rotation_z(jnp.float32(np.pi / 2)))
  np.testing.assert_allclose(q, [np.sqrt(0.5), 0, 0, np.sqrt(0.5)], atol=1e-6)


def test_transform_apply_compose_invert():
  key1, key2 = jax.random.split(jax.random.key(3))
  t1 = geometry.make_transform(geometry.random_so3(key1), jnp.array([1.0, -2.0, 0.5]))
  t2 = geometry.make_transform(geometry.random_so3(key2), jnp.array([0.0, 3.0, -1.0]))
  pts = jax.random.normal(key1, (20, 3))
  np.testing.assert_allclose(
      geometry.apply_transform(geometry.compose_transforms(t1, t2), pts),
      geometry.apply_transform(t1, geometry.apply_transform(t2, pts)), atol=1e-5)
  np.testing.assert_allclose(geometry.invert_transform(t1) @ t1, np.eye(4), atol=1e-5)


def test_geodesic_angle():
  r = geometry.rotation_z(jnp.deg2rad(30.0))
  assert float(geometry.geodesic_angle_deg(jnp.eye(3), r)) == pytest.approx(30.0, abs=1e-3)


def test_euler_sum_rre_matches_hand_computation():
  # R_gt^T R_est = Rz(10 deg) Ry(-5 deg) Rx(2 deg): ZYX angles (10, -5, 2) -> |.| sum 17 deg.
  def rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])

  def ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])

  rel = np.asarray(geometry.rotation_z(np.deg2rad(10.0))) @ ry(np.deg2rad(-5.0)) @ rx(np.deg2rad(2.0))
  r_gt = np.asarray(geometry.random_so3(jax.random.key(4)), np.float64)
  r_est = r_gt @ rel
  np.testing.assert_allclose(geometry.rotm2eul_zyx(jnp.asarray(rel, jnp.float32)),
                             np.deg2rad([10.0, -5.0, 2.0]), atol=1e-5)
  assert float(geometry.euler_sum_rre_deg(jnp.asarray(r_gt, jnp.float32),
                                          jnp.asarray(r_est, jnp.float32))) == pytest.approx(17.0, abs=1e-2)


def test_translation_error():
  assert float(geometry.translation_error(jnp.array([1.0, 2, 3]), jnp.array([1.0, 5, 7]))) == 5.0
