"""The CF module: closed-form rigid registration from all descriptor pairs.

    min_{R,t} sum_i sum_j w_ij ||R p_i + t - q_j||^2,  w_ij = exp(-||f_i - g_j||^2 / alpha)

is a weighted Kabsch problem over the k_P x k_Q pairs. Its weighted centroids
and 3x3 cross-covariance reduce to matrix products with the k_P x k_Q weight
matrix, so memory is O(k_P k_Q) and the stacked point sets of the paper's
Eq. (4) are never built.

The rotation is the special-orthogonal polar factor of the covariance. Its
derivative is given in closed form (`nearest_rotation`'s custom JVP), whose
denominators are sums s_i + s_j of singular values rather than the
differences s_i^2 - s_j^2 of a generic SVD gradient: repeated singular values
(symmetric scenes) are harmless, and planar, collinear or coincident geometry
gives finite gradients.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

_REL_EPS = 1e-6  # smallest s_i + s_j, relative to s_1, in the JVP's denominators


def _polar_parts(m: jax.Array):
  """SVD pieces of the special polar factor of m [3, 3]."""
  u, s, vt = jnp.linalg.svd(m)
  d = jnp.sign(jnp.linalg.det(u @ vt))
  d = jnp.where(d == 0, 1.0, d)
  # Flip the weakest direction when the best orthogonal fit is a reflection.
  signs = jnp.array([1.0, 1.0, 0.0], m.dtype) + jnp.array([0.0, 0.0, 1.0], m.dtype) * d
  r = (u * signs) @ vt
  return r, s * signs, vt


@jax.custom_jvp
def nearest_rotation(m: jax.Array) -> jax.Array:
  """The rotation R in SO(3) maximising tr(R^T m) for m [3, 3] (reflection-safe)."""
  return _polar_parts(m)[0]


@nearest_rotation.defjvp
def _nearest_rotation_jvp(primals, tangents):
  (m,), (dm,) = primals, tangents
  r, s_signed, vt = _polar_parts(m)
  # m = R P with P = V diag(s_signed) V^T symmetric; dR = R Omega with Omega
  # skew and, in the basis V: Omega_hat_ij (s_i + s_j) = [V^T (R^T dm - dm^T R) V]_ij.
  x = r.T @ dm
  x_hat = vt @ (x - x.T) @ vt.T
  denom = s_signed[:, None] + s_signed[None, :]
  floor = _REL_EPS * s_signed[0] + jnp.finfo(m.dtype).tiny
  omega_hat = x_hat / jnp.maximum(denom, floor)
  return r, r @ (vt.T @ omega_hat @ vt)


def descriptor_weights(feat_p: jax.Array, feat_q: jax.Array, alpha: float,
                       mask_p: jax.Array | None = None,
                       mask_q: jax.Array | None = None,
                       attention_p: jax.Array | None = None,
                       attention_q: jax.Array | None = None) -> jax.Array:
  """w_ij = exp(-||f_i - g_j||^2 / alpha) [* a_i * b_j], normalised to sum 1 over valid pairs.

  attention_p [kP], attention_q [kQ] >= 0: optional per-cluster factors (the
  self-supervised detector: attention is then trained through the CF module).

  feat_p [kP, D], feat_q [kQ, D], masks [kP] / [kQ] bool -> [kP, kQ]. The
  normalisation (a common factor) leaves R and t unchanged and is done in log
  space, so no weight underflows to an all-zero matrix for small alpha.
  """
  d2 = (jnp.sum(feat_p * feat_p, -1)[:, None] + jnp.sum(feat_q * feat_q, -1)[None, :]
        - 2.0 * feat_p @ feat_q.T)
  logits = -jnp.maximum(d2, 0.0) / alpha
  tiny = jnp.finfo(logits.dtype).tiny
  if attention_p is not None:
    logits = logits + jnp.log(jnp.maximum(attention_p, tiny))[:, None]
  if attention_q is not None:
    logits = logits + jnp.log(jnp.maximum(attention_q, tiny))[None, :]
  pair_mask = jnp.ones(logits.shape, bool)
  if mask_p is not None:
    pair_mask &= mask_p[:, None]
  if mask_q is not None:
    pair_mask &= mask_q[None, :]
  logits = jnp.where(pair_mask, logits, -jnp.inf)
  top = jax.lax.stop_gradient(jnp.max(logits))
  w = jnp.where(pair_mask, jnp.exp(logits - jnp.where(jnp.isfinite(top), top, 0.0)), 0.0)
  return w / jnp.maximum(jnp.sum(w), jnp.finfo(w.dtype).tiny)


def weighted_kabsch(xyz_p: jax.Array, xyz_q: jax.Array, w: jax.Array) -> tuple[jax.Array, jax.Array]:
  """argmin_{R,t} sum_ij w_ij ||R p_i + t - q_j||^2 for all pairs.

  xyz_p [kP, 3], xyz_q [kQ, 3] metres, w [kP, kQ] >= 0 summing to 1
  -> R [3, 3], t [3] metres, mapping P into Q's frame.
  """
  row, col = jnp.sum(w, 1), jnp.sum(w, 0)
  mean_p, mean_q = row @ xyz_p, col @ xyz_q
  p_c, q_c = xyz_p - mean_p, xyz_q - mean_q
  cov = p_c.T @ (w @ q_c)  # H = sum_ij w_ij (p_i - p_mean)(q_j - q_mean)^T
  r = nearest_rotation(cov.T)
  return r, mean_q - r @ mean_p


def cf_solve(xyz_p: jax.Array, xyz_q: jax.Array, feat_p: jax.Array, feat_q: jax.Array,
             alpha: float = 1.0, mask_p: jax.Array | None = None,
             mask_q: jax.Array | None = None, attention_p: jax.Array | None = None,
             attention_q: jax.Array | None = None) -> tuple[jax.Array, jax.Array]:
  """The CF module (paper Eq. 2-5): R, t from all k_P x k_Q descriptor pairs.

  Args:
    xyz_p: [kP, 3] cluster centers of cloud P, metres.
    xyz_q: [kQ, 3] cluster centers of cloud Q, metres.
    feat_p: [kP, D] descriptors of P.
    feat_q: [kQ, D] descriptors of Q.
    alpha: temperature of the weights (paper: 1).
    mask_p, mask_q: [kP] / [kQ] bool, clusters that take part.
    attention_p, attention_q: optional [kP] / [kQ] >= 0 factors of the weights.

  Returns:
    R [3, 3] and t [3] metres with R p + t ~ q. Finite for any finite input.
  """
  w = descriptor_weights(feat_p, feat_q, alpha, mask_p, mask_q, attention_p, attention_q)
  return weighted_kabsch(xyz_p, xyz_q, w)
