"""Rigid-body geometry: rotations, transforms, quaternions and rotation errors.

All functions are pure `jax.numpy` and broadcast over leading batch axes. The
rotation, quaternion, transform and error helpers also accept numpy arrays and
then compute in numpy (float64 on the host, e.g. for ground-truth files).
Conventions:
  * points are row vectors `[..., N, 3]` in metres; a rotation acts as `p @ R.T`;
  * a 4x4 transform `T` maps points of its source frame into its target frame;
  * quaternions are scalar-first `(w, x, y, z)`, as MATLAB's `rotm2quat` and the
    3DFeat-Net `groundtruths.txt` files write them.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np


def _xp(*arrays):
  """numpy for host arrays (keeps float64), jax.numpy otherwise."""
  return np if all(isinstance(a, (np.ndarray, np.generic, float, int)) for a in arrays) else jnp


def rotation_z(theta: jax.Array) -> jax.Array:
  """Rotation about +z by `theta` radians (right-handed). theta: [...] -> [..., 3, 3]."""
  xp = _xp(theta)
  c, s = xp.cos(theta), xp.sin(theta)
  zero, one = xp.zeros_like(theta), xp.ones_like(theta)
  rows = [
      xp.stack([c, -s, zero], -1),
      xp.stack([s, c, zero], -1),
      xp.stack([zero, zero, one], -1),
  ]
  return xp.stack(rows, -2)


def yaw_deg(transform: jax.Array) -> jax.Array:
  """Rotation about z of transforms or rotations [..., 3+, 3+], degrees in (-180, 180]."""
  xp = _xp(transform)
  return xp.rad2deg(xp.arctan2(transform[..., 1, 0], transform[..., 0, 0]))


def random_z_angle(key: jax.Array, shape: tuple[int, ...], sigma: float,
                   clip: float | None = None) -> jax.Array:
  """Angles phi ~ N(0, sigma^2) radians, optionally clipped to [-clip, clip] (paper §III-D)."""
  phi = sigma * jax.random.normal(key, shape)
  if clip is not None:
    phi = jnp.clip(phi, -clip, clip)
  return phi


def random_so3(key: jax.Array, shape: tuple[int, ...] = ()) -> jax.Array:
  """Uniformly distributed rotations [*shape, 3, 3] (normalised Gaussian quaternions)."""
  q = jax.random.normal(key, (*shape, 4))
  q = q / jnp.linalg.norm(q, axis=-1, keepdims=True)
  return quaternion_to_matrix(q)


def quaternion_to_matrix(q: jax.Array) -> jax.Array:
  """Unit quaternion [..., 4] (w, x, y, z) -> rotation matrix [..., 3, 3]."""
  xp = _xp(q)
  q = q / xp.linalg.norm(q, axis=-1, keepdims=True)
  w, x, y, z = xp.moveaxis(q, -1, 0)
  rows = [
      xp.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
      xp.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
      xp.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
  ]
  return xp.stack(rows, -2)


def matrix_to_quaternion(r: jax.Array) -> jax.Array:
  """Rotation matrix [..., 3, 3] -> unit quaternion [..., 4] (w, x, y, z), w >= 0.

  Uses the largest of the four candidate denominators (Shepperd's method), so it
  is accurate for every rotation including 180 degrees.
  """
  xp = _xp(r)
  m = r
  trace = m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2]
  cands = xp.stack([
      xp.stack([1 + trace, m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0],
                 m[..., 1, 0] - m[..., 0, 1]], -1),
      xp.stack([m[..., 2, 1] - m[..., 1, 2], 1 + 2 * m[..., 0, 0] - trace,
                 m[..., 0, 1] + m[..., 1, 0], m[..., 0, 2] + m[..., 2, 0]], -1),
      xp.stack([m[..., 0, 2] - m[..., 2, 0], m[..., 0, 1] + m[..., 1, 0],
                 1 + 2 * m[..., 1, 1] - trace, m[..., 1, 2] + m[..., 2, 1]], -1),
      xp.stack([m[..., 1, 0] - m[..., 0, 1], m[..., 0, 2] + m[..., 2, 0],
                 m[..., 1, 2] + m[..., 2, 1], 1 + 2 * m[..., 2, 2] - trace], -1),
  ], -2)  # [..., 4 candidates, 4]
  diag = xp.stack([1 + trace, 1 + 2 * m[..., 0, 0] - trace,
                    1 + 2 * m[..., 1, 1] - trace, 1 + 2 * m[..., 2, 2] - trace], -1)
  best = xp.argmax(diag, axis=-1)
  q = xp.take_along_axis(cands, best[..., None, None], axis=-2)[..., 0, :]
  q = q / xp.linalg.norm(q, axis=-1, keepdims=True)
  return xp.where(q[..., :1] < 0, -q, q)


def make_transform(rotation: jax.Array, translation: jax.Array) -> jax.Array:
  """R [..., 3, 3], t [..., 3] metres -> homogeneous T [..., 4, 4]."""
  xp = _xp(rotation, translation)
  top = xp.concatenate([rotation, translation[..., :, None]], -1)
  bottom = xp.broadcast_to(xp.array([0.0, 0.0, 0.0, 1.0], top.dtype),
                            (*top.shape[:-2], 1, 4))
  return xp.concatenate([top, bottom], -2)


def apply_transform(transform: jax.Array, points: jax.Array) -> jax.Array:
  """T [..., 4, 4] applied to points [..., N, 3] metres -> [..., N, 3]."""
  xp = _xp(transform, points)
  r, t = transform[..., :3, :3], transform[..., :3, 3]
  return points @ xp.swapaxes(r, -1, -2) + t[..., None, :]


def compose_transforms(t_ab: jax.Array, t_bc: jax.Array) -> jax.Array:
  """T_ac = T_ab @ T_bc: first map c -> b, then b -> a."""
  return t_ab @ t_bc


def invert_transform(transform: jax.Array) -> jax.Array:
  """Inverse of a rigid transform [..., 4, 4] without a general matrix inverse."""
  xp = _xp(transform)
  r, t = transform[..., :3, :3], transform[..., :3, 3]
  rt = xp.swapaxes(r, -1, -2)
  return make_transform(rt, -(rt @ t[..., :, None])[..., 0])


def geodesic_angle_deg(r_a: jax.Array, r_b: jax.Array) -> jax.Array:
  """Angle of r_a^T r_b in degrees, [..., 3, 3] x2 -> [...]; the modern RRE."""
  xp = _xp(r_a, r_b)
  rel_trace = xp.einsum('...ij,...ij->...', r_a, r_b)  # tr(r_a^T r_b)
  cos = xp.clip((rel_trace - 1.0) / 2.0, -1.0, 1.0)
  return xp.degrees(xp.arccos(cos))


def rotm2eul_zyx(r: jax.Array) -> jax.Array:
  """MATLAB `rotm2eul(R, 'ZYX')`: [..., 3, 3] -> [..., 3] angles (z, y, x) radians."""
  xp = _xp(r)
  sy = xp.clip(-r[..., 2, 0], -1.0, 1.0)
  y = xp.arcsin(sy)
  singular = xp.abs(sy) > 1.0 - 1e-6
  z = xp.where(singular, xp.arctan2(-r[..., 0, 1], r[..., 1, 1]),
                xp.arctan2(r[..., 1, 0], r[..., 0, 0]))
  x = xp.where(singular, 0.0, xp.arctan2(r[..., 2, 1], r[..., 2, 2]))
  return xp.stack([z, y, x], -1)


def euler_sum_rre_deg(r_gt: jax.Array, r_est: jax.Array) -> jax.Array:
  """The paper's RRE: sum of |ZYX Euler angles| of r_gt^T r_est, in degrees (docs/method.md §4)."""
  xp = _xp(r_gt, r_est)
  rel = xp.swapaxes(r_gt, -1, -2) @ r_est
  return xp.degrees(xp.sum(xp.abs(rotm2eul_zyx(rel)), -1))


def translation_error(t_gt: jax.Array, t_est: jax.Array) -> jax.Array:
  """RTE = ||t_est - t_gt|| metres, [..., 3] x2 -> [...]."""
  xp = _xp(t_gt, t_est)
  return xp.linalg.norm(t_est - t_gt, axis=-1)
