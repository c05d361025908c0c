"""Self-rotation and branch resampling (ssd_jax.augment, objective.resample_branch)."""

import jax
import jax.numpy as jnp
import ml_collections
import numpy as np
import pytest

from ssd_jax import augment, objective


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
  cfg = ml_collections.ConfigDict({'branch_dropout': 0.0, 'branch_crop_shift': 0.0,
                                   'branch_crop_radius': 20.0})
  cfg.update(overrides)
  return cfg


def test_resampled_branches_are_two_different_samplings():
  pts = jnp.asarray(np.random.default_rng(0).uniform(-15, 15, (2, 3000, 3)), jnp.float32)
  valid = jnp.ones((2, 3000), bool)
  off = objective.resample_branch(jax.random.key(0), pts, valid, _model_cfg())
  assert bool(off.all())                                  # the paper: every point, both
  cfg = _model_cfg(branch_dropout=0.5, branch_crop_shift=4.0, branch_crop_radius=14.0)
  v1 = np.asarray(objective.resample_branch(jax.random.key(1), pts, valid, cfg))
  v2 = np.asarray(objective.resample_branch(jax.random.key(2), pts, valid, cfg))
  both = (v1 & v2).sum(1)
  assert np.all(both > 100) and np.all(both < 0.8 * np.minimum(v1.sum(1), v2.sum(1)))
  np.testing.assert_array_equal(
      v1, objective.resample_branch(jax.random.key(1), pts, valid, cfg))
