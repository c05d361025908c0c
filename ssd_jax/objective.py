"""The self-supervised objective of the paper (REFERENCE §2), as a pure function.

    cloud --self_rotate--> (PC1, PC2) --jitter--> centers + clusters
      --shared FeatureNet--> descriptors --cf_solve--> R --rotation_loss--> loss
"""

from __future__ import annotations

from typing import Any

import flax.linen as nn
import jax
import jax.numpy as jnp
import ml_collections

from ssd_jax import augment, cf, geometry, grouping, losses


def self_supervised_loss(model: nn.Module, variables: dict[str, Any], key: jax.Array,
                         points: jax.Array, valid: jax.Array,
                         cfg: ml_collections.ConfigDict, train: bool = True):
  """Loss of one batch of unlabeled clouds.

  Args:
    model: a `FeatureNet`.
    variables: {'params', 'batch_stats'}.
    key: PRNG key for rotation, jitter and center sampling.
    points: [B, N, 3] metres, each cloud centred on its sensor.
    valid: [B, N] bool mask of real points.
    cfg: the `model` section of the config.
    train: BatchNorm in training mode (batch statistics, updated running stats).

  Returns:
    (loss, (metrics, new_batch_stats)); metrics hold per-pair rotation errors.
  """
  k_rot, k_jit1, k_jit2, k_c1, k_c2 = jax.random.split(key, 5)
  b = points.shape[0]
  pc2, r_gt = augment.self_rotate(k_rot, points, cfg.rotation_sigma, cfg.rotation_clip)
  pc1 = augment.jitter(k_jit1, points, cfg.jitter_sigma, cfg.jitter_clip)
  pc2 = augment.jitter(k_jit2, pc2, cfg.jitter_sigma, cfg.jitter_clip)
  both = jnp.concatenate([pc1, pc2], 0)
  both_valid = jnp.concatenate([valid, valid], 0)

  # Same key in both branches: FPS starts at the same point and (PC2 being PC1
  # rotated, in the same order) picks almost the same centers, as the reference.
  center_keys = (k_c1, k_c2) if cfg.independent_centers else (k_c1, k_c1)
  idx1, cvalid1 = grouping.sample_centers(center_keys[0], pc1, valid, cfg.num_clusters,
                                          cfg.center_sampling)
  idx2, cvalid2 = grouping.sample_centers(center_keys[1], pc2, valid, cfg.num_clusters,
                                          cfg.center_sampling)
  idx = jnp.concatenate([idx1, idx2], 0)
  centers = jnp.take_along_axis(both, idx[..., None], axis=1)  # [2B, k, 3]
  clusters, has_nb = grouping.extract_clusters(both, both_valid, centers, cfg.radius,
                                               cfg.num_samples)

  # Both branches in one call: shared weights, and BatchNorm statistics over both.
  if train:
    (desc, _, _), mutated = model.apply(variables, clusters, train=True,
                                        mutable=['batch_stats'])
    new_batch_stats = mutated['batch_stats']
  else:
    desc, _, _ = model.apply(variables, clusters, train=False)
    new_batch_stats = variables['batch_stats']

  mask = has_nb & jnp.concatenate([cvalid1, cvalid2], 0)
  r_est, _ = jax.vmap(lambda xp, xq, fp, fq, mp, mq: cf.cf_solve(xp, xq, fp, fq, cfg.alpha, mp, mq))(
      centers[:b], centers[b:], desc[:b], desc[b:], mask[:b], mask[b:])
  per_pair = losses.rotation_loss(r_est, r_gt, cfg.loss)
  metrics = {
      'loss': jnp.mean(per_pair),
      'rotation_error_deg': jnp.mean(geometry.geodesic_angle_deg(r_gt, r_est)),
      'rotation_deg': jnp.mean(geometry.geodesic_angle_deg(r_gt, jnp.eye(3))),
  }
  return metrics['loss'], (metrics, new_batch_stats)
