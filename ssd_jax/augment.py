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


# 3DFeat-Net's augmentations (REFERENCE §3), one draw per cloud of a batch [B, N, 3].

def rotate_small(key: jax.Array, points: jax.Array, sigma: float = 0.06,
                 clip: float = 0.18) -> jax.Array:
  """RotateSmall: small rotations about x, y and z, each angle N(0, sigma^2) radians
  clipped to +-clip, about the sensor origin."""
  ang = jnp.clip(sigma * jax.random.normal(key, (points.shape[0], 3)), -clip, clip)
  c, s = jnp.cos(ang), jnp.sin(ang)
  one, zero = jnp.ones_like(c[:, 0]), jnp.zeros_like(c[:, 0])
  rx = jnp.stack([one, zero, zero, zero, c[:, 0], -s[:, 0], zero, s[:, 0], c[:, 0]], -1)
  ry = jnp.stack([c[:, 1], zero, s[:, 1], zero, one, zero, -s[:, 1], zero, c[:, 1]], -1)
  rot = rx.reshape(-1, 3, 3) @ ry.reshape(-1, 3, 3) @ geometry.rotation_z(ang[:, 2])
  return points @ jnp.swapaxes(rot, -1, -2)


def shift(key: jax.Array, points: jax.Array, max_shift: float = 0.1) -> jax.Array:
  """Shift: one uniform offset in [-max_shift, max_shift]^3 metres per cloud."""
  offset = jax.random.uniform(key, (points.shape[0], 1, 3), points.dtype, -max_shift, max_shift)
  return points + offset


def rotate_1d(key: jax.Array, points: jax.Array) -> jax.Array:
  """Rotate1D: a uniform random rotation about z per cloud."""
  phi = jax.random.uniform(key, points.shape[:1], points.dtype, -jnp.pi, jnp.pi)
  return points @ jnp.swapaxes(geometry.rotation_z(phi), -1, -2)
