"""The 3DFeat-Net network body as Flax Linen modules (docs/method.md §1).

The network is a pure function of explicit variables `{'params', 'batch_stats'}`
and inputs: `FeatureNet().apply(variables, clusters, train=...)`.

Shapes: clusters `[..., k, c, 3]`, unitless (relative to the center, divided by
the ball radius). Outputs per cluster: descriptor `[..., k, D]` (unit norm),
attention `[..., k]` (>= 0) and orientation `[..., k]` (radians about z).
"""

from __future__ import annotations

from typing import Sequence

import flax.linen as nn
import jax
import jax.numpy as jnp

from ssd_jax import grouping, layers

DESCRIPTOR_DIMS = (16, 32, 64, 128)


class MLP(nn.Module):
  """Shared per-point / per-cluster MLP: Dense -> BatchNorm -> ReLU for each width."""
  features: Sequence[int]
  bn_momentum: float = 0.99

  @nn.compact
  def __call__(self, x: jax.Array, train: bool, context: jax.Array | None = None) -> jax.Array:
    """x [..., A] -> [..., features[-1]]. context [..., B] (x then [..., c, A]): the first
    layer sees each point's features concatenated with its cluster's context
    (`BroadcastDense`)."""
    # One 2-D GEMM per layer: with the leading axes flattened, the weight
    # gradient contracts a single axis, which XLA:CPU runs as a plain GEMM
    # (contracting several batch axes at once was ~5x slower in the backward).
    lead = x.shape[:-1]
    if context is None:
      x = x.reshape(-1, x.shape[-1])
    for i, width in enumerate(self.features):
      if i == 0 and context is not None:
        x = layers.BroadcastDense(width, use_bias=False, name='Dense_0')(x, context)
        x = x.reshape(-1, width)
      else:
        x = nn.Dense(width, use_bias=False, name=f'Dense_{i}')(x)
      x = layers.BatchNormReLU(self.bn_momentum)(x, train)
    return x.reshape(*lead, x.shape[-1])


class Detector(nn.Module):
  """3DFeat-Net part 1: attention and z-orientation per cluster."""
  bn_momentum: float = 0.99

  @nn.compact
  def __call__(self, clusters: jax.Array, train: bool) -> tuple[jax.Array, jax.Array]:
    x = MLP((64, 128, 256), self.bn_momentum, name='point_mlp')(clusters, train)
    x = jnp.max(x, axis=-2)  # max-pool over the c points of a cluster
    x = MLP((128, 64), self.bn_momentum, name='cluster_mlp')(x, train)
    attention = nn.softplus(nn.Dense(1, name='attention')(x))[..., 0]
    xy = nn.Dense(2, name='orientation')(x)
    # atan2 of the raw 2-vector equals atan2 of its L2-normalised version; the
    # guard only keeps the gradient finite at the (measure-zero) origin.
    both_zero = jnp.all(xy == 0, axis=-1)
    angle = jnp.arctan2(xy[..., 1], jnp.where(both_zero, 1.0, xy[..., 0]))
    return attention, angle


class EquivariantDetector(nn.Module):
  """Attention and a z-orientation that turns with the cluster by construction.

  The paper's `Detector` must learn that its orientation turns with the cluster;
  it learns it only over the angles training shows it. Here every point i gets a
  weight w_i from features that do not change under a rotation about z (its
  horizontal distance from the center rho_i, its height z_i, and what the cluster
  pools from those), and the orientation is the angle of sum_i w_i (x_i, y_i). Turn
  the cluster by phi and every (x_i, y_i) turns by phi while the w_i stay, so the
  angle shifts by exactly phi for every phi in [0, 2 pi), and the descriptor of the
  canonically rotated cluster is invariant. Attention comes from the same invariant
  features, so it is invariant too.
  """
  bn_momentum: float = 0.99

  @nn.compact
  def __call__(self, clusters: jax.Array, train: bool) -> tuple[jax.Array, jax.Array]:
    xy, z = clusters[..., :2], clusters[..., 2:]
    rho = jnp.sqrt(jnp.sum(xy * xy, -1, keepdims=True) + 1e-12)
    x = MLP((64, 128, 256), self.bn_momentum, name='point_mlp')(
        jnp.concatenate([rho, z], -1), train)
    pooled = jnp.max(x, axis=-2)
    g = MLP((128, 64), self.bn_momentum, name='cluster_mlp')(pooled, train)
    attention = nn.softplus(nn.Dense(1, name='attention')(g))[..., 0]
    w = layers.BroadcastDense(1, name='orientation')(x, g)          # [..., c, 1], invariant
    v = jnp.mean(w * xy, axis=-2)                            # [..., 2], turns with the cluster
    both_zero = jnp.all(v == 0, axis=-1)
    angle = jnp.arctan2(v[..., 1], jnp.where(both_zero, 1.0, v[..., 0]))
    return attention, angle


ORIENTATION_HEADS = ('mlp', 'equivariant')


class Descriptor(nn.Module):
  """3DFeat-Net part 2: canonically oriented cluster -> L2-normalised descriptor."""
  dim: int = 32
  bn_momentum: float = 0.99

  @nn.compact
  def __call__(self, clusters: jax.Array, train: bool) -> jax.Array:
    x = MLP((32, 64), self.bn_momentum, name='point_mlp1')(clusters, train)
    pooled = jnp.max(x, axis=-2)
    width = 256 if self.dim > 64 else 128
    x = MLP((width,), self.bn_momentum, name='point_mlp2')(x, train, context=pooled)
    x = jnp.max(x, axis=-2)
    x = nn.Dense(self.dim, name='out')(x)
    return x * jax.lax.rsqrt(jnp.sum(x * x, -1, keepdims=True) + 1e-12)


class FeatureNet(nn.Module):
  """Detector + orientation + descriptor.

  Attributes:
    descriptor_dim: D in {16, 32, 64, 128}.
    use_orientation: rotate each cluster by the predicted angle before the
      descriptor (False: 3DFeat-Net's descriptor pre-training stage).
    orientation_head: 'mlp' (3DFeat-Net's `Detector`, the paper) or 'equivariant'
      (`EquivariantDetector`: the orientation turns with the cluster by construction).
  """
  descriptor_dim: int = 32
  use_orientation: bool = True
  bn_momentum: float = 0.99
  orientation_head: str = 'mlp'

  def setup(self):
    if self.descriptor_dim not in DESCRIPTOR_DIMS:
      raise ValueError(f'descriptor_dim must be one of {DESCRIPTOR_DIMS}, '
                       f'got {self.descriptor_dim}')
    if self.orientation_head not in ORIENTATION_HEADS:
      raise ValueError(f'orientation_head must be one of {ORIENTATION_HEADS}, '
                       f'got {self.orientation_head!r}')
    detector = Detector if self.orientation_head == 'mlp' else EquivariantDetector
    self.detector = detector(self.bn_momentum)
    self.descriptor = Descriptor(self.descriptor_dim, self.bn_momentum)

  def __call__(self, clusters: jax.Array, train: bool = False):
    """clusters [..., k, c, 3] -> (descriptors [..., k, D], attention [..., k], angle [..., k])."""
    if self.use_orientation:
      attention, angle = self.detect(clusters, train)
    else:  # descriptor-only: the detector is neither run nor created
      angle = jnp.zeros(clusters.shape[:-2], clusters.dtype)
      attention = jnp.ones_like(angle)
    return self.describe(clusters, angle, train), attention, angle

  def detect(self, clusters: jax.Array, train: bool = False):
    """clusters [..., k, c, 3] -> (attention [..., k], orientation [..., k] radians)."""
    return self.detector(clusters, train)

  def describe(self, clusters: jax.Array, angle: jax.Array, train: bool = False) -> jax.Array:
    """Descriptors of clusters [..., k, c, 3] seen in the frame rotated by angle [..., k]."""
    return self.descriptor(grouping.rotate_clusters(clusters, angle), train)


def variables_template(model_config):
  """Shapes and dtypes of the variables {'params', 'batch_stats'} of `create(model_config)`
  (a pytree of `jax.ShapeDtypeStruct`), to check restored weights against."""
  net = create(model_config)
  points = jax.ShapeDtypeStruct((1, 1, model_config.num_samples, 3), jnp.float32)
  return jax.eval_shape(lambda p: net.init(jax.random.key(0), p, train=False), points)


def create(model_config) -> FeatureNet:
  """The `FeatureNet` that a config's `model` section describes (the one place it is
  built, for training and inference alike); a stored run's config goes through
  `config_tools.upgrade.upgrade` first."""
  return FeatureNet(descriptor_dim=model_config.descriptor_dim,
                    use_orientation=model_config.use_orientation,
                    bn_momentum=model_config.bn_momentum,
                    orientation_head=model_config.orientation_head)
