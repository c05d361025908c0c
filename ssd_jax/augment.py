"""Random self-rotation, jitter and branch resampling drawn with `jax.random`.

The paper's self-supervision (docs/method.md §2) rotates and jitters; the branch
resampling (point dropout, offset crops) is this project's label-free remedy for two
branches that are otherwise the same points.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ssd_jax import geometry


def self_rotate(key: jax.Array, points: jax.Array, sigma: float,
                clip: float | None, distribution: str = 'gaussian'
                ) -> tuple[jax.Array, jax.Array]:
  """PC2 = R_random PC1 with R_random about z by `self_rotation_angle`.

  points [B, N, 3] metres -> (rotated [B, N, 3], R_random [B, 3, 3]). The
  rotation is about the sensor origin, which is where the clouds are centred.
  """
  phi = self_rotation_angle(key, points.shape[:1], distribution, sigma, clip)
  rot = geometry.rotation_z(phi)
  return points @ jnp.swapaxes(rot, -1, -2), rot


SELF_ROTATIONS = ('gaussian', 'uniform')


def self_rotation_angle(key: jax.Array, shape: tuple[int, ...], distribution: str,
                        sigma: float, clip: float | None) -> jax.Array:
  """Self-rotation angles [*shape] radians: 'gaussian' N(0, sigma^2) clipped to +-clip
  (the paper), or 'uniform' over the whole circle [-pi, pi) (real scan pairs come at
  any relative yaw; the Gaussian almost never shows the network one beyond ~70 deg)."""
  if distribution == 'gaussian':
    return geometry.random_z_angle(key, shape, sigma, clip)
  if distribution == 'uniform':
    return jax.random.uniform(key, shape, minval=-jnp.pi, maxval=jnp.pi)
  raise ValueError(f'self-rotation must be one of {SELF_ROTATIONS}, got {distribution!r}')


def point_dropout(key: jax.Array, valid: jax.Array, max_rate: float) -> jax.Array:
  """Drop a random share of each cloud's points: valid [B, N] -> valid [B, N].

  Each cloud draws its rate uniformly in [0, max_rate], then each point is dropped
  with that probability. Applied to the two branches with their own keys, it makes
  them two different samplings of the same surfaces, at different densities.
  """
  k_rate, k_point = jax.random.split(key)
  rate = jax.random.uniform(k_rate, valid.shape[:1] + (1,), maxval=max_rate)
  return valid & (jax.random.uniform(k_point, valid.shape) >= rate)


def crop_around_offset(key: jax.Array, points: jax.Array, valid: jax.Array, shift: float,
                       radius: float) -> jax.Array:
  """Keep the points within `radius` metres (horizontally) of a point drawn uniformly in
  the disk of radius `shift` around the sensor: valid [B, N] -> valid [B, N].

  Two branches cropped around their own offsets overlap only partly, as two scans
  from a sensor that moved.
  """
  k_r, k_a = jax.random.split(key)
  b = points.shape[0]
  r = shift * jnp.sqrt(jax.random.uniform(k_r, (b,)))
  a = jax.random.uniform(k_a, (b,), minval=-jnp.pi, maxval=jnp.pi)
  center = jnp.stack([r * jnp.cos(a), r * jnp.sin(a)], -1)[:, None, :]
  return valid & (jnp.sum((points[..., :2] - center) ** 2, -1) <= radius ** 2)


def jitter(key: jax.Array, points: jax.Array, sigma: float, clip: float | None) -> jax.Array:
  """Per-point Gaussian noise N(0, sigma^2) metres, clipped to +-clip: [..., 3] -> [..., 3]."""
  noise = sigma * jax.random.normal(key, points.shape, points.dtype)
  if clip is not None:
    noise = jnp.clip(noise, -clip, clip)
  return points + noise


# 3DFeat-Net's augmentations (docs/method.md §5), one draw per cloud of a batch [B, N, 3].

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
