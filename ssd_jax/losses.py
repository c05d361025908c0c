"""Training objectives."""

from __future__ import annotations

import jax
import jax.numpy as jnp

ROTATION_LOSSES = ('frobenius', 'squared_frobenius')


def rotation_loss(r_est: jax.Array, r_gt: jax.Array, kind: str = 'frobenius') -> jax.Array:
  """Deviation of R R_gt^T from the identity, per pair: [..., 3, 3] x2 -> [...].

  kind='frobenius': ||I - R R_gt^T||_F (paper Eq. 6);
  kind='squared_frobenius': its square, as the reference code trains.
  """
  diff = jnp.eye(3, dtype=r_est.dtype) - r_est @ jnp.swapaxes(r_gt, -1, -2)
  sq = jnp.sum(diff * diff, axis=(-2, -1))
  if kind == 'squared_frobenius':
    return sq
  if kind == 'frobenius':
    # The norm's gradient is bounded near a perfect fit (|d/dtheta| = sqrt(2)),
    # but sqrt'(0) is infinite: evaluate it away from exactly 0.
    safe = jnp.where(sq > 1e-12, sq, 1.0)
    return jnp.where(sq > 1e-12, jnp.sqrt(safe), 0.0)
  raise ValueError(f'rotation loss must be one of {ROTATION_LOSSES}, got {kind!r}')
