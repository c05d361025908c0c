"""Building blocks of the network that are what Flax's own are, but fast on a CPU.

Training on 2 CPU cores is memory-bound in these layers (docs/notes/speed.md), so
they avoid the passes XLA:CPU would otherwise make; each computes what its plain Flax
counterpart computes (tested against autodiff and `nn.Dense`), and the parameter names
are the same, so weights carry over.

  * `BatchNormReLU`: BatchNorm then ReLU with a hand-written VJP (two fused passes, no
    stored normalised copy);
  * `BroadcastDense`: Dense on [per-point features, cluster context] without building
    the concatenation.
"""

from __future__ import annotations

import flax.linen as nn
import jax
import jax.numpy as jnp

BN_EPSILON = 1e-3  # TensorFlow's default, as 3DFeat-Net trained with


def _bn_stats(x):
  mean = jnp.mean(x, 0)
  var = jnp.maximum(jnp.mean(x * x, 0) - mean * mean, 0.0)
  return mean, var


@jax.custom_vjp
def batch_norm_relu(x: jax.Array, scale: jax.Array, bias: jax.Array):
  """relu(BatchNorm(x)) with batch statistics; x [P, C] -> (y [P, C], mean [C], var [C]).

  Equal to the autodiff of the textbook formula, but its backward reads x and
  the incoming gradient in two fused passes and stores no normalised copy:
  on CPU the layers are memory-bound and this halves BatchNorm's share of a
  step. `mean` and `var` feed the running averages only; no gradient flows
  back through them.
  """
  return _batch_norm_relu_fwd(x, scale, bias)[0]


def _batch_norm_relu_fwd(x, scale, bias):
  mean, var = _bn_stats(x)
  rstd = jax.lax.rsqrt(var + BN_EPSILON)
  y = jnp.maximum((x - mean) * (rstd * scale) + bias, 0.0)
  return (y, mean, var), (x, y, mean, rstd, scale)


def _batch_norm_relu_bwd(res, cotangents):
  x, y, mean, rstd, scale = res
  dy = cotangents[0]
  g = jnp.where(y > 0, dy, 0.0)
  xhat = (x - mean) * rstd
  dbias = jnp.sum(g, 0)
  dscale = jnp.sum(g * xhat, 0)
  n = x.shape[0]
  dx = (rstd * scale) * (g - dbias / n - xhat * (dscale / n))
  return dx, dscale, dbias


batch_norm_relu.defvjp(_batch_norm_relu_fwd, _batch_norm_relu_bwd)


class BatchNormReLU(nn.Module):
  """BatchNorm (learned scale and bias, running mean/var) followed by ReLU on [P, C]."""
  momentum: float = 0.99

  @nn.compact
  def __call__(self, x: jax.Array, train: bool) -> jax.Array:
    c = x.shape[-1]
    scale = self.param('scale', nn.initializers.ones, (c,))
    bias = self.param('bias', nn.initializers.zeros, (c,))
    ra_mean = self.variable('batch_stats', 'mean', jnp.zeros, (c,))
    ra_var = self.variable('batch_stats', 'var', jnp.ones, (c,))
    if not train:
      return nn.relu((x - ra_mean.value) * (jax.lax.rsqrt(ra_var.value + BN_EPSILON) * scale)
                     + bias)
    y, mean, var = batch_norm_relu(x, scale, bias)
    if not self.is_initializing():
      ra_mean.value = self.momentum * ra_mean.value + (1 - self.momentum) * mean
      ra_var.value = self.momentum * ra_var.value + (1 - self.momentum) * var
    return y


class BroadcastDense(nn.Module):
  """Dense on concat([x, g broadcast over the c points]) without building the concatenation.

  x [..., c, A] per point, g [..., B] per cluster -> [..., c, features]. The kernel is
  [A + B, features], the one `nn.Dense` would hold for the concatenated input (same
  initialiser), so weights carry over; the cluster part is one row per cluster instead of
  c copies, which on CPU saves the memory pass over the [..., c, A + B] concatenation
  and the g half of the per-point GEMM.
  """
  features: int
  use_bias: bool = True

  @nn.compact
  def __call__(self, x: jax.Array, g: jax.Array) -> jax.Array:
    a = x.shape[-1]
    kernel = self.param('kernel', nn.initializers.lecun_normal(),
                        (a + g.shape[-1], self.features))
    # A 2-D GEMM over the flattened points: see MLP.
    y = (x.reshape(-1, a) @ kernel[:a]).reshape(*x.shape[:-1], self.features)
    y = y + (g @ kernel[a:])[..., None, :]
    if self.use_bias:
      y = y + self.param('bias', nn.initializers.zeros, (self.features,))
    return y
