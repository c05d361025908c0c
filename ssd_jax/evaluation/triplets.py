"""What the triplet objective can learn from its training triplets (3DFeat-Net, docs/method.md §5).

Two measurements on the trainer's fixed probe triplets:

- `checkpoint_probe`: a checkpoint's attention-weighted triplet loss and accuracy under a
  chosen set of augmentations, e.g. the clouds as stored against every cloud turned by
  its own random angle (Rotate1D). A descriptor whose gain vanishes under Rotate1D
  learned the clouds' orientation, not their local shape.
- `fpfh_probe`: the same hardest-match statistics for FPFH, a hand-crafted descriptor
  that is rotation invariant by construction: how much rotation-invariant signal the
  triplets offer at all.

Accuracy is the share of anchor clusters whose best match in the positive cloud is
closer than their best match in the negative cloud (0.5 is chance).
"""

from __future__ import annotations

from typing import Sequence

import jax
import jax.numpy as jnp
import ml_collections
import numpy as np

from ssd_jax import geometry, grouping, inference, objective, train
from ssd_jax.registration import features


def checkpoint_probe(model: inference.Model, config: ml_collections.ConfigDict,
                     triplets: np.ndarray, augmentations: Sequence[str]) -> dict[str, float]:
  """Triplet loss of `model` on triplets [T, 3, N, 3] metres with running BatchNorm
  statistics, the trainer's probe key and `augmentations` in place of the config's.
  -> {'loss', 'triplet_accuracy', 'positive_distance', 'negative_distance'}."""
  config = config.copy_and_resolve_references()
  config.model.augmentations = tuple(augmentations)
  state = train.TrainState(step=jnp.zeros((), jnp.int32), params=model.variables['params'],
                           batch_stats=model.variables['batch_stats'], opt_state=None,
                           rng=None)
  probe = jax.jit(lambda s, p, k: train.probe_step(s, p, k, model=train.create_model(config),
                                                   config=config))
  metrics = probe(state, jnp.asarray(triplets), jax.random.key(config.seed + 2))
  return {k: float(v) for k, v in metrics.items()}


def turn_clouds(triplets: np.ndarray, max_angle: float, seed: int = 0) -> np.ndarray:
  """Each cloud of triplets [T, 3, N, 3] metres turned about z by its own angle drawn
  uniformly from [-max_angle, max_angle] radians (max_angle pi: Rotate1D) -> same shape.
  Drawn on the host from `seed`, so every checkpoint sees the same turns."""
  phi = np.random.default_rng(seed).uniform(-max_angle, max_angle, triplets.shape[:2])
  rz = np.asarray(geometry.rotation_z(phi), np.float32)   # [T, 3, 3, 3]
  return np.einsum('tcij,tcnj->tcni', rz, triplets).astype(np.float32)


def fpfh_probe(triplets: np.ndarray, num_centers: int, seed: int = 0, margin: float = 0.2,
               fpfh_max_nn: int = features.FPFH_MAX_NN, hinge: str = 'cloud'
               ) -> dict[str, float]:
  """Hardest-match triplet statistics of L2-normalised FPFH on triplets [T, 3, N, 3] metres,
  at `num_centers` FPS centres per cloud (one key per triplet, so identical clouds get
  identical centres), all clusters weighted alike; `hinge` as in
  `objective.attention_weighted_triplet`. -> {'loss', 'triplet_accuracy', ...}."""
  stats = []
  for t, triplet in enumerate(triplets):
    key = jax.random.fold_in(jax.random.key(seed), t)
    descs = []
    for cloud in triplet:
      idx, _ = grouping.sample_centers(key, jnp.asarray(cloud)[None],
                                       jnp.ones((1, len(cloud)), bool), num_centers)
      d = features.fpfh(cloud, np.asarray(idx[0]), max_nn=fpfh_max_nn)
      descs.append(d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12))
    desc = jnp.asarray(np.stack(descs))
    loss, s = objective.attention_weighted_triplet(
        desc, jnp.zeros(desc.shape[:2]), jnp.ones(desc.shape[:2], bool), margin, hinge)
    stats.append({'loss': float(loss), **{k: float(v) for k, v in s.items()}})
  return {k: float(np.mean([s[k] for s in stats])) for k in stats[0]}
