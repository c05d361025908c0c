"""Random self-rotation and jitter drawn with `jax.random` (REFERENCE §2)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ssd_jax import geometry


def self_rotate(key: jax.Array, points: jax.Array, sigma: float,
                clip: float | None) -> tuple[jax.Array, jax.Array]:
  """PC2 = R_random PC1 with R_random about z, phi ~ N(0, sigma^2) clipped.

  points [B, N, 3] metres -> (rotated [B, N, 3], R_random [B, 3, 3]). The
  rotation is about the sensor origin, which is where the clouds are centred.
  """
  phi = geometry.random_z_angle(key, points.shape[:1], sigma, clip)
  rot = geometry.rotation_z(phi)
  return points @ jnp.swapaxes(rot, -1, -2), rot


def jitter(key: jax.Array, points: jax.Array, sigma: float, clip: float | None) -> jax.Array:
  """Per-point Gaussian noise N(0, sigma^2) metres, clipped to +-clip: [..., 3] -> [..., 3]."""
  noise = sigma * jax.random.normal(key, points.shape, points.dtype)
  if clip is not None:
    noise = jnp.clip(noise, -clip, clip)
  return points + noise
