"""The precision test of paper Fig. 4 (docs/method.md §4).

For every keypoint of cloud 1, its nearest descriptor neighbour among cloud 2's
keypoints; the error is the distance between the keypoint and that neighbour
moved by the ground truth T_12. Only keypoints of cloud 1 within 0.75 m of some
point of the moved cloud 2 (the overlap) count. The curve is the fraction of
counted keypoints, pooled over all pairs, whose error is below x.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from scipy import spatial
from tqdm import auto as tqdm

from ssd_jax import geometry
from ssd_jax.infra import distributed
from ssd_jax.evaluation import feature_store
from ssd_jax.registration import matching

OVERLAP_RADIUS = 0.75                                   # metres
THRESHOLDS = np.round(np.arange(1, 101) * 0.1, 1)       # x = 0.1 ... 10 m


def overlap_mask(keypoints1: np.ndarray, cloud2: np.ndarray, transform: np.ndarray,
                 radius: float = OVERLAP_RADIUS) -> np.ndarray:
  """keypoints1 [K, 3] lying within `radius` metres of some point of cloud2 [N, 3]
  moved by transform [4, 4] (T_12) -> [K] bool."""
  moved = geometry.apply_transform(np.asarray(transform, np.float64),
                                   np.asarray(cloud2, np.float64))
  dist, _ = spatial.cKDTree(moved).query(np.asarray(keypoints1, np.float64),
                                         distance_upper_bound=radius)
  return dist < radius


def match_errors(keypoints1: np.ndarray, descriptors1: np.ndarray, keypoints2: np.ndarray,
                 descriptors2: np.ndarray, transform: np.ndarray) -> np.ndarray:
  """[K1] metres: distance of each keypoint of cloud 1 to its descriptor nearest
  neighbour in cloud 2, moved into cloud 1's frame by transform (T_12)."""
  nn = matching.nearest_neighbour_matches(descriptors1, descriptors2)
  matched = geometry.apply_transform(np.asarray(transform, np.float64),
                                     np.asarray(keypoints2, np.float64)[nn])
  return np.linalg.norm(np.asarray(keypoints1, np.float64) - matched, axis=1)


def precision_curve(errors: np.ndarray, thresholds: np.ndarray = THRESHOLDS) -> np.ndarray:
  """Fraction of errors [M] below each threshold [T] -> [T] (NaN when M = 0)."""
  errors = np.asarray(errors, np.float64)
  if errors.size == 0:
    return np.full(len(thresholds), np.nan)
  return np.mean(errors[:, None] < np.asarray(thresholds)[None, :], axis=0)


def pair_errors(pair, row: str, store: feature_store.FeatureStore,
                overlap_radius: float = OVERLAP_RADIUS) -> tuple[np.ndarray, int]:
  """Errors [M] of the overlapping keypoints of one pair and row, and K1 (all keypoints)."""
  f1, f2 = store.features(pair.cloud1, row), store.features(pair.cloud2, row)
  if len(f1.xyz) == 0 or len(f2.xyz) == 0:
    return np.zeros(0), len(f1.xyz)
  errors = match_errors(f1.xyz, f1.descriptors, f2.xyz, f2.descriptors, pair.transform)
  keep = overlap_mask(f1.xyz, store.cloud(pair.cloud2), pair.transform, overlap_radius)
  return errors[keep], len(f1.xyz)


def evaluate_precision(pairs: Sequence, rows: Sequence[str], store: feature_store.FeatureStore,
                       overlap_radius: float = OVERLAP_RADIUS, progress: bool = True,
                       desc: str = 'precision') -> dict[str, dict]:
  """-> {row: {'errors': [M] pooled over pairs, 'keypoints': all cloud-1 keypoints,
  'curve': precision at THRESHOLDS}}."""
  per_pair = distributed.map_items(   # over several processes: each its share, gathered
      lambda n, pair: {row: pair_errors(pair, row, store, overlap_radius) for row in rows},
      pairs, lambda ns: tqdm.tqdm(ns, desc=desc, unit='pair', disable=not progress))
  errors = {row: [p[row][0] for p in per_pair] for row in rows}
  counts = {row: sum(p[row][1] for p in per_pair) for row in rows}
  out = {}
  for row in rows:
    e = np.concatenate(errors[row]) if errors[row] else np.zeros(0)
    out[row] = {'errors': e, 'keypoints': counts[row], 'curve': precision_curve(e)}
  return out


def value_at(curve: np.ndarray, x: float, thresholds: np.ndarray = THRESHOLDS) -> float:
  """The curve's value at threshold x (one of `thresholds`)."""
  hits = np.flatnonzero(np.isclose(thresholds, x))
  if not len(hits):
    raise ValueError(f'x = {x} m is not one of the curve thresholds')
  return float(curve[hits[0]])
