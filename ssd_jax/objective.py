"""The self-supervised objective of the paper (docs/method.md §2), as a pure function.

    cloud --self_rotate--> (PC1, PC2) --jitter--> centers + clusters
      --shared FeatureNet--> descriptors --cf_solve--> R --rotation_loss--> loss
"""

from __future__ import annotations

import functools
from typing import Any

import flax.linen as nn
import jax
import jax.numpy as jnp
import ml_collections

from ssd_jax import augment, cf, geometry, grouping

ROTATION_LOSSES = ('frobenius', 'squared_frobenius')
CONTRASTIVE_ROWS = ('all', 'two_view')


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


def _apply(model, variables, clusters, train):
  """-> ((descriptors, attention, angle), batch_stats after the call)."""
  if train:
    out, mutated = model.apply(variables, clusters, train=True, mutable=['batch_stats'])
    return out, mutated['batch_stats']
  return model.apply(variables, clusters, train=False), variables['batch_stats']


def partner_indices(centers1: jax.Array, pc2: jax.Array, valid2: jax.Array,
                    r_gt: jax.Array, key: jax.Array | None = None,
                    jitter: float = 0.0) -> jax.Array:
  """For each of PC1's centres, PC2's valid point nearest to it once turned by R_gt (PC2
  is its view turned: rows p R_gt^T), or, with `jitter` > 0 metres, nearest to a point
  drawn uniformly (`key`) from the horizontal disc of that radius around it.
  centers1 [B, k, 3], pc2 [B, N, 3] metres, valid2 [B, N], r_gt [B, 3, 3] -> [B, k] int32
  indices into pc2."""
  if jitter > 0 and key is None:
    raise ValueError(f'partner_indices: a jitter of {jitter} m needs a PRNG key')
  target = jnp.einsum('bki,bji->bkj', centers1, r_gt)
  if jitter > 0:
    # Registration's keypoints are sampled in each cloud on its own, so a keypoint's
    # counterpart lies up to about half their spacing away: partners as far off train for
    # that gap (configs/experiments/rescan_jitter.py measures it). Horizontal, as R_gt
    # turns about z only.
    k_r, k_a = jax.random.split(key)
    r = jitter * jnp.sqrt(jax.random.uniform(k_r, target.shape[:2]))
    a = jax.random.uniform(k_a, target.shape[:2], maxval=2 * jnp.pi)
    target = target + jnp.stack([r * jnp.cos(a), r * jnp.sin(a), jnp.zeros_like(r)], -1)
  d2 = jax.vmap(grouping.squared_distances)(target, pc2)
  return jnp.argmin(jnp.where(valid2[:, None, :], d2, jnp.inf), axis=-1).astype(jnp.int32)


def _branch_clusters(keys, pc1, valid1, pc2, valid2, cfg, r_gt):
  """Cluster centres of both branches (`cfg.center_sampling`; PC2's the partners of PC1's
  with `cfg.partner_centers`) and their ball-query clusters, PC1's batch first:
  -> (centers [2B, k, 3], clusters [2B, k, c, 3], mask [2B, k])."""
  idx1, cvalid1 = grouping.sample_centers(keys[0], pc1, valid1, cfg.num_clusters,
                                          cfg.center_sampling)
  if cfg.partner_centers:
    centers1 = jnp.take_along_axis(pc1, idx1[..., None], axis=1)
    idx2 = partner_indices(centers1, pc2, valid2, r_gt, keys[1], cfg.partner_jitter)
    cvalid2 = jnp.take_along_axis(valid2, idx2, axis=1)
  else:
    idx2, cvalid2 = grouping.sample_centers(keys[1], pc2, valid2, cfg.num_clusters,
                                            cfg.center_sampling)
  both = jnp.concatenate([pc1, pc2], 0)
  centers = jnp.take_along_axis(both, jnp.concatenate([idx1, idx2], 0)[..., None], axis=1)
  clusters, has_nb = grouping.extract_clusters(
      both, jnp.concatenate([valid1, valid2], 0), centers, cfg.radius, cfg.num_samples)
  return centers, clusters, has_nb & jnp.concatenate([cvalid1, cvalid2], 0)


def correspondence_nce(centers1: jax.Array, centers2: jax.Array, desc1: jax.Array,
                       desc2: jax.Array, mask1: jax.Array, mask2: jax.Array,
                       radius: float, temperature: float) -> jax.Array:
  """InfoNCE at corresponding cluster centres of one pair of branches, both in PC1's
  frame: centers [k, 3] metres, unit descriptors [k, D], masks [k]. Each centre of PC1
  with a centre of PC2 within `radius` scores its descriptor against all of PC2's
  (similarity / temperature, a softmax): the loss is minus the log of the share on its
  partners. -> scalar (0 where no centre has a partner)."""
  near = jnp.sum((centers1[:, None] - centers2[None]) ** 2, -1) < radius ** 2
  partner = near & mask1[:, None] & mask2[None]
  # A large finite "minus infinity": a row with no partner stays finite, and so do the
  # gradients `where` passes through it.
  logits = jnp.where(mask2[None], desc1 @ desc2.T / temperature, -1e9)
  log_share = (jax.nn.logsumexp(jnp.where(partner, logits, -1e9), axis=1)
               - jax.nn.logsumexp(logits, axis=1))
  has = partner.any(1)
  return -jnp.sum(jnp.where(has, log_share, 0.0)) / jnp.maximum(has.sum(), 1)


def self_supervised_loss(model: nn.Module, variables: dict[str, Any], key: jax.Array,
                         points: jax.Array, valid: jax.Array,
                         cfg: ml_collections.ConfigDict, train: bool = True):
  """The paper's loss (Eq. 6) of a batch of unlabeled clouds, ||I - R R_gt^T||_F (plus
  `contrastive_weight` times `correspondence_nce` where that is > 0, on every row or, with
  `contrastive_rows` 'two_view', on the rows whose second view is not their own points;
  the paper's: 0).

  model: a `FeatureNet` with variables {'params', 'batch_stats'}; key: the step's PRNG
  key; points [B, N, 3] metres, valid [B, N] (or a second view each: see
  `augment.self_supervised_branches`); cfg: the config's `model` section; train: BatchNorm
  in training mode. -> (loss, (metrics, new batch_stats)); metrics hold the mean CF
  rotation error and the mean self-rotation, degrees.
  """
  *_, k_c1, k_c2 = jax.random.split(key, 5)
  pc1, valid1, pc2, valid2, r_gt = augment.self_supervised_branches(key, points, valid, cfg)
  # One key for both branches (the reference's): FPS starts at the same point, and PC2
  # being PC1 turned, in the same order, picks almost the same centres.
  keys = (k_c1, k_c2) if cfg.independent_centers else (k_c1, k_c1)
  centers, clusters, mask = _branch_clusters(keys, pc1, valid1, pc2, valid2, cfg, r_gt)
  # Both branches in one call: shared weights, BatchNorm statistics over both.
  (desc, attention, _), new_batch_stats = _apply(model, variables, clusters, train)
  # The self-supervised detector (an extension) weighs pair ij by w_ij * a_i * b_j, so
  # attention learns from single clouds; the paper's CF has no attention (a = b = 1).
  att = attention if cfg.attention_in_cf else jnp.ones_like(attention)
  b = pc1.shape[0]
  r_est, _ = jax.vmap(lambda xp, xq, fp, fq, mp, mq, ap, aq: cf.cf_solve(
      xp, xq, fp, fq, cfg.alpha, mp, mq, ap, aq))(
          centers[:b], centers[b:], desc[:b], desc[b:], mask[:b], mask[b:], att[:b], att[b:])
  per_pair = rotation_loss(r_est, r_gt, cfg.loss)
  if cfg.contrastive_weight > 0:
    # PC2's centres back in PC1's frame (PC2 = its view turned by R_gt: rows p R_gt^T).
    back = jnp.einsum('bkj,bji->bki', centers[b:], r_gt)
    nce = jax.vmap(functools.partial(correspondence_nce, radius=cfg.contrastive_radius,
                                     temperature=cfg.contrastive_temperature))(
        centers[:b], back, desc[:b], desc[b:], mask[:b], mask[b:])
    if cfg.contrastive_rows == 'two_view':
      # A row whose second view is its own points (the paper's pair; every row of a batch
      # of single clouds) shares the scan's rings in both branches, which the InfoNCE
      # would reward matching; only rows with another view of the place count, averaged
      # over those rows.
      two_view = (jnp.any(points[:, 0] != points[:, 1], axis=(1, 2)) if points.ndim == 4
                  else jnp.zeros(b, bool))
      nce = jnp.where(two_view, nce, 0.0) * b / jnp.maximum(jnp.sum(two_view), 1)
    per_pair = per_pair + cfg.contrastive_weight * nce
  metrics = {'loss': jnp.mean(per_pair),
             'rotation_error_deg': jnp.mean(geometry.geodesic_angle_deg(r_gt, r_est)),
             'rotation_deg': jnp.mean(geometry.geodesic_angle_deg(r_gt, jnp.eye(3)))}
  return metrics['loss'], (metrics, new_batch_stats)


def _best_match_distance(feat_a: jax.Array, feat_o: jax.Array, mask_o: jax.Array) -> jax.Array:
  """For each anchor descriptor [kA, D], the Euclidean distance to its nearest valid
  descriptor of the other cloud [kO, D] (mask [kO]) -> [kA]."""
  d2 = (jnp.sum(feat_a * feat_a, -1)[:, None] + jnp.sum(feat_o * feat_o, -1)[None, :]
        - 2.0 * feat_a @ feat_o.T)
  d2 = jnp.where(mask_o[None, :], d2, jnp.inf)
  # The floor keeps sqrt's gradient finite for identical descriptors.
  return jnp.sqrt(jnp.maximum(jnp.min(d2, axis=1), 1e-12))


TRIPLET_HINGES = ('cloud', 'cluster')
ATTENTION_NORMALIZATIONS = ('softmax', 'sum')


def attention_weighted_triplet(desc: jax.Array, attention: jax.Array, mask: jax.Array,
                               margin: float, hinge: str = 'cloud',
                               normalization: str = 'softmax'
                               ) -> tuple[jax.Array, dict[str, jax.Array]]:
  """3DFeat-Net's loss (docs/method.md §5) for one triplet.

  desc [3, k, D] (anchor, positive, negative), attention [3, k] >= 0, mask [3, k]
  bool. For anchor cluster i: d_pos = distance to its best match in the positive
  cloud, d_neg the same in the negative; w = the anchor's attention normalised over
  its valid clusters, by a softmax (`normalization='softmax'`, the 3DFeat-Net paper's wording) or
  by its sum (`'sum'`, 3DFeat-Net's released code). The hinge sits on each cluster
  (`hinge='cluster'`: sum_i w_i max(0, d_pos_i - d_neg_i + margin)) or on the weighted
  sums (`'cloud'`, the released code: max(0, sum_i w_i d_pos_i - sum_i w_i d_neg_i +
  margin)). -> (loss, stats).
  """
  d_pos = _best_match_distance(desc[0], desc[1], mask[1])
  d_neg = _best_match_distance(desc[0], desc[2], mask[2])
  if normalization == 'softmax':
    w = jax.nn.softmax(jnp.where(mask[0], attention[0], -jnp.inf))
  elif normalization == 'sum':
    a = jnp.where(mask[0], attention[0], 0.0)
    w = a / jnp.maximum(jnp.sum(a), 1e-12)
  else:
    raise ValueError(f"normalization must be 'softmax' or 'sum', got {normalization!r}")
  stats = {'positive_distance': jnp.sum(w * d_pos), 'negative_distance': jnp.sum(w * d_neg),
           'triplet_accuracy': jnp.sum(w * (d_pos < d_neg))}
  if hinge == 'cluster':
    loss = jnp.sum(w * jnp.maximum(d_pos - d_neg + margin, 0.0))
  elif hinge == 'cloud':
    loss = jnp.maximum(stats['positive_distance'] - stats['negative_distance'] + margin, 0.0)
  else:
    raise ValueError(f"hinge must be 'cluster' or 'cloud', got {hinge!r}")
  return loss, stats


def triplet_loss(model: nn.Module, variables: dict[str, Any], key: jax.Array,
                 points: jax.Array, valid: jax.Array, cfg: ml_collections.ConfigDict,
                 train: bool = True):
  """3DFeat-Net's weakly supervised loss of a batch of triplets.

  Args:
    points: [B, 3, N, 3] metres: anchor, positive and negative cloud of each triplet.
    valid: [B, 3, N] bool.
    cfg: the `model` section; `augmentations` lists which of jitter, rotate_small,
      shift, rotate_1d run (each cloud draws its own).
  Returns:
    (loss, (metrics, new_batch_stats)).
  """
  b, three, n, _ = points.shape
  flat, flat_valid = points.reshape(b * three, n, 3), valid.reshape(b * three, n)
  k_aug, k_centers = jax.random.split(key)
  aug_keys = jax.random.split(k_aug, 4)
  if 'jitter' in cfg.augmentations:
    flat = augment.jitter(aug_keys[0], flat, cfg.jitter_sigma, cfg.jitter_clip)
  if 'rotate_small' in cfg.augmentations:
    flat = augment.rotate_small(aug_keys[1], flat)
  if 'shift' in cfg.augmentations:
    flat = augment.shift(aug_keys[2], flat)
  if 'rotate_1d' in cfg.augmentations:
    flat = augment.rotate_1d(aug_keys[3], flat)
  idx, cvalid = grouping.sample_centers(k_centers, flat, flat_valid, cfg.num_clusters,
                                        cfg.center_sampling)
  centers = jnp.take_along_axis(flat, idx[..., None], axis=1)
  clusters, has_nb = grouping.extract_clusters(flat, flat_valid, centers, cfg.radius,
                                               cfg.num_samples)
  (desc, attention, _), new_batch_stats = _apply(model, variables, clusters, train)
  k = cfg.num_clusters
  per_triplet, stats = jax.vmap(lambda d, a, m: attention_weighted_triplet(
      d, a, m, cfg.margin, cfg.triplet_hinge, cfg.attention_normalization))(
      desc.reshape(b, three, k, -1), attention.reshape(b, three, k),
      (has_nb & cvalid).reshape(b, three, k))
  metrics = {'loss': jnp.mean(per_triplet), **{key_: jnp.mean(v) for key_, v in stats.items()}}
  return metrics['loss'], (metrics, new_batch_stats)


# The triplet objective's fixed probe: this many training-size batches of triplets. Under
# Rotate1D, 8 triplets with one draw of turns and centres moved a checkpoint's probe loss
# by +-0.03 from one draw to the next, more than the training changed it.
PROBE_BATCHES = 32


def probe_triplets(dataset, config: ml_collections.ConfigDict):
  """The triplet objective's fixed probe from a `datasets.TripletDataset`:
  [batch_size * PROBE_BATCHES, 3, N, 3] metres, the same at every evaluation of a run."""
  return dataset.batch(config.seed + 1, 0, config.train.batch_size * PROBE_BATCHES,
                       config.data.num_points)


def triplet_probe(model: nn.Module, variables: dict[str, Any], key: jax.Array,
                  triplets: jax.Array, cfg: ml_collections.ConfigDict,
                  batch_size: int) -> dict[str, jax.Array]:
  """Mean `triplet_loss` metrics of fixed triplets [M * batch_size, 3, N, 3] metres with
  running BatchNorm statistics: one batch at a time, so the memory is a training batch's,
  each with its own draw of augmentations and centres. The triplet loss of a random
  batch is too noisy to read a trend from; the same triplets and draws at every
  evaluation are not."""
  if triplets.shape[0] % batch_size:
    raise ValueError(f'triplet_probe: {triplets.shape[0]} triplets is not a multiple of '
                     f'the training batch size {batch_size}')
  batches = triplets.reshape(-1, batch_size, *triplets.shape[1:])
  keys = jax.random.split(key, batches.shape[0])
  valid = jnp.ones(batches.shape[1:-1], bool)
  per_batch = jax.lax.map(lambda xs: triplet_loss(model, variables, xs[1], xs[0], valid, cfg,
                                                  train=False)[1][0], (batches, keys))
  return jax.tree.map(lambda v: jnp.mean(v, 0), per_batch)


OBJECTIVES = {'self_supervised': self_supervised_loss, 'triplet': triplet_loss}
