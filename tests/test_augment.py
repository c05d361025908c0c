"""Self-rotation and branch resampling (ssd_jax.augment, augment.resample_branch)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ssd_jax import augment
from ssd_jax.configs.training import paper


def test_uniform_self_rotation_covers_the_circle_and_gaussian_stays_clipped():
  key = jax.random.key(0)
  uniform = np.asarray(augment.self_rotation_angle(key, (20_000,), 'uniform', 0.6, 1.8))
  counts, _ = np.histogram(uniform, bins=8, range=(-np.pi, np.pi))
  assert counts.min() > 0.9 * len(uniform) / 8     # every 45° bin gets its share
  gauss = np.asarray(augment.self_rotation_angle(key, (20_000,), 'gaussian', 0.6, 1.8))
  assert np.abs(gauss).max() <= 1.8 + 1e-6 and np.mean(np.abs(gauss) > np.pi / 2) < 0.02
  with pytest.raises(ValueError, match='self-rotation must be one of'):
    augment.self_rotation_angle(key, (2,), 'vonmises', 0.6, 1.8)


def test_point_dropout_rate_is_bounded_and_deterministic():
  valid = jnp.ones((64, 4000), bool)
  kept = augment.point_dropout(jax.random.key(3), valid, 0.5)
  share = np.asarray(kept.mean(1))
  assert share.min() > 0.45 and share.max() <= 1.0 and share.std() > 0.05   # rates differ
  np.testing.assert_array_equal(kept, augment.point_dropout(jax.random.key(3), valid, 0.5))
  assert not np.array_equal(kept, augment.point_dropout(jax.random.key(4), valid, 0.5))


def test_offset_crop_keeps_a_disk_around_a_shifted_sensor():
  rng = np.random.default_rng(0)
  pts = jnp.asarray(rng.uniform(-20, 20, (8, 5000, 3)), jnp.float32)
  kept = np.asarray(augment.crop_around_offset(jax.random.key(1), pts, jnp.ones((8, 5000), bool),
                                               shift=4.0, radius=10.0))
  for b in range(8):
    xy = np.asarray(pts[b, kept[b], :2])
    center = (xy.max(0) + xy.min(0)) / 2          # the disk's center, from what it kept
    assert np.linalg.norm(center) <= 4.0 + 0.5
    assert np.linalg.norm(xy - center, axis=1).max() <= 10.0 + 0.5
    assert 0.12 < kept[b].mean() < 0.25          # pi 10^2 / 40^2 = 0.196 of the square


def _model_cfg(**overrides):
  """The paper config's model section (every branch change off) with `overrides`."""
  cfg = paper.get_config().model
  cfg.update(overrides)
  return cfg


def test_resampled_branches_are_two_different_samplings():
  pts = jnp.asarray(np.random.default_rng(0).uniform(-15, 15, (2, 3000, 3)), jnp.float32)
  valid = jnp.ones((2, 3000), bool)
  off = augment.resample_branch(jax.random.key(0), pts, valid, _model_cfg())
  assert bool(off.all())                                  # the paper: every point, both
  cfg = _model_cfg(branch_dropout=0.5, branch_crop_shift=4.0, branch_crop_radius=14.0)
  v1 = np.asarray(augment.resample_branch(jax.random.key(1), pts, valid, cfg))
  v2 = np.asarray(augment.resample_branch(jax.random.key(2), pts, valid, cfg))
  both = (v1 & v2).sum(1)
  assert np.all(both > 100) and np.all(both < 0.8 * np.minimum(v1.sum(1), v2.sum(1)))
  np.testing.assert_array_equal(
      v1, augment.resample_branch(jax.random.key(1), pts, valid, cfg))


def _spherical_points(rng, b, n, max_range=30.0):
  r = rng.uniform(3, max_range, (b, n))
  el, az = np.radians(rng.uniform(-20, 5, (b, n))), rng.uniform(-np.pi, np.pi, (b, n))
  return jnp.asarray(np.stack([r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az),
                               r * np.sin(el)], -1), jnp.float32)


def test_beam_resample_keeps_rings_of_a_sparser_unit():
  pts = _spherical_points(np.random.default_rng(0), 16, 4000)
  valid = jnp.ones((16, 4000), bool)
  always = np.asarray(augment.beam_resample(jax.random.key(0), pts, valid, 1.0, (2.0, 2.0), 0.2))
  el = np.degrees(np.arctan2(pts[..., 2], jnp.linalg.norm(pts[..., :2], axis=-1)))
  for b in range(16):   # the kept elevations fall in bands 2 degrees apart, 0.4 wide
    frac = np.mod(el[b, always[b]], 2.0)
    spread = np.ptp(np.mod(frac - frac[0] + 1.0, 2.0))
    assert spread <= 0.4 + 1e-4
    assert 0.12 < always[b].mean() < 0.28         # 0.4 / 2 of the points
  never = augment.beam_resample(jax.random.key(0), pts, valid, 0.0, (2.0, 2.0))
  assert bool(never.all())
  half = np.asarray(augment.beam_resample(jax.random.key(1), jnp.tile(pts, (4, 1, 1)),
                                          jnp.ones((64, 4000), bool), 0.5, (0.7, 2.5)))
  assert 16 < np.sum(half.mean(1) < 0.6) < 48      # about half of the clouds re-sampled


def test_fov_crop_keeps_a_sector():
  pts = _spherical_points(np.random.default_rng(1), 8, 4000)
  kept = np.asarray(augment.fov_crop(jax.random.key(0), pts, jnp.ones((8, 4000), bool), 1.0,
                                     (90.0, 90.0)))
  for b in range(8):
    az = np.degrees(np.arctan2(pts[b, kept[b], 1], pts[b, kept[b], 0]))
    heading = np.degrees(np.angle(np.mean(np.exp(1j * np.radians(az)))))
    assert np.abs((az - heading + 180) % 360 - 180).max() <= 45 + 1.0
    assert 0.2 < kept[b].mean() < 0.3               # a quarter of the circle


def test_sensor_change_that_leaves_too_few_points_is_not_applied():
  pts = _spherical_points(np.random.default_rng(2), 2, 1000)
  valid = jnp.ones((2, 1000), bool)
  # 1,000 points through a 90 degree sector of 2-degree rings keep ~50: fewer than
  # augment.MIN_BRANCH_POINTS, so the branch stays as it was.
  cfg = _model_cfg(branch_sensor_rate=1.0, branch_beam_spacing=(2.0, 2.0), branch_fov_rate=1.0,
                   branch_fov=(90.0, 90.0))
  out = augment.resample_branch(jax.random.key(0), pts, valid, cfg)
  assert bool(out.all())
  big = _spherical_points(np.random.default_rng(2), 2, 8000)
  out = np.asarray(augment.resample_branch(jax.random.key(0), big, jnp.ones((2, 8000), bool),
                                             _model_cfg(branch_sensor_rate=1.0,
                                                        branch_beam_spacing=(2.0, 2.0))))
  assert np.all((out.sum(1) >= augment.MIN_BRANCH_POINTS) & (out.mean(1) < 0.3))
