"""Keypoint repeatability: how often a detector fires at the same place in two scans.

For a pair with ground truth T_12, the repeatability of cloud 1's keypoints is the
fraction that have a keypoint of cloud 2 (moved by T_12) within `radius` metres.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from scipy import spatial
from tqdm import auto as tqdm

from ssd_jax import geometry
from ssd_jax.infra import distributed
from ssd_jax.evaluation import feature_store

RADIUS = 0.5   # metres


def keypoint_repeatability(keypoints1: np.ndarray, keypoints2: np.ndarray,
                           transform: np.ndarray, radius: float = RADIUS) -> float:
  """keypoints1 [K1, 3], keypoints2 [K2, 3] metres, transform [4, 4] T_12 -> fraction of
  keypoints1 with a moved keypoint of cloud 2 within radius (NaN when K1 = 0)."""
  if len(keypoints1) == 0:
    return float('nan')
  if len(keypoints2) == 0:
    return 0.0
  moved = geometry.apply_transform(np.asarray(transform, np.float64),
                                   np.asarray(keypoints2, np.float64))
  dist, _ = spatial.cKDTree(moved).query(np.asarray(keypoints1, np.float64),
                                         distance_upper_bound=radius)
  return float(np.mean(dist <= radius))


def evaluate_repeatability(pairs: Sequence, sources: Sequence[str],
                           store: feature_store.FeatureStore, radius: float = RADIUS,
                           progress: bool = True) -> dict[str, dict]:
  """-> {source: {'repeatability': mean over pairs, 'keypoints': mean count per cloud}}."""
  def measure(n, pair) -> dict[str, tuple[float, int, int]]:
    out = {}
    for s in sources:
      k1 = store.cloud(pair.cloud1)[store.keypoints(pair.cloud1, s)]
      k2 = store.cloud(pair.cloud2)[store.keypoints(pair.cloud2, s)]
      out[s] = (keypoint_repeatability(k1, k2, pair.transform, radius), len(k1), len(k2))
    return out

  per_pair = distributed.map_items(   # over several processes: each its share, gathered
      measure, pairs,
      lambda ns: tqdm.tqdm(ns, desc='repeatability', unit='pair', disable=not progress))
  rep = {s: [p[s][0] for p in per_pair] for s in sources}
  counts = {s: [c for p in per_pair for c in p[s][1:]] for s in sources}
  return {s: {'repeatability': float(np.nanmean(rep[s])) if rep[s] else float('nan'),
              'keypoints': float(np.mean(counts[s])) if counts[s] else float('nan')}
          for s in sources}
