"""Descriptor matching without a detector (paper Table III and its text, docs/method.md §4).

Each pair of 4 m cluster crops gets one descriptor per cluster, at the cluster's
center (the origin), with a 2 m radius. The error is the false-positive rate at
95 % recall: the threshold is the descriptor distance that 95 % of the positive
pairs do not exceed; FPR = share of negative pairs at or below it. The
ISS-filtered variant keeps the pairs where both clusters have an ISS keypoint
(docs/method.md §4 parameters, detected on the cluster) within r_th of the center.
"""

from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np
from tqdm import auto as tqdm

from ssd_jax import inference
from ssd_jax.infra import distributed
from ssd_jax.data import clean, clusters as clusters_lib, io
from ssd_jax.registration import features as features_lib, keypoints

RECALL = 0.95
RADIUS = 2.0                     # metres, for every descriptor
R_TH = (0.1, 0.2, 0.3, 0.4)      # metres


def fpr_at_recall(distances: np.ndarray, labels: np.ndarray,
                  recall: float = RECALL) -> tuple[float, float]:
  """-> (FPR, threshold). distances [P] descriptor distances, labels [P] 1 = match.

  The threshold is the smallest distance t with at least `recall` of the positives
  at d <= t; FPR is the share of negatives with d <= t. NaN for a set without
  positives or negatives.
  """
  distances, labels = np.asarray(distances, np.float64), np.asarray(labels)
  pos, neg = np.sort(distances[labels == 1]), distances[labels == 0]
  if len(pos) == 0 or len(neg) == 0:
    return float('nan'), float('nan')
  # 1e-9 keeps recall * n that is an integer in exact arithmetic from rounding up.
  k = max(1, math.ceil(recall * len(pos) - 1e-9))
  threshold = float(pos[k - 1])
  return float(np.mean(neg <= threshold)), threshold


def roc_curve(distances: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
  """(FPR [T], recall [T]) as the distance threshold sweeps every observed value."""
  distances, labels = np.asarray(distances, np.float64), np.asarray(labels)
  order = np.argsort(distances, kind='stable')
  is_pos = labels[order] == 1
  tpr = np.cumsum(is_pos) / max(is_pos.sum(), 1)
  fpr = np.cumsum(~is_pos) / max((~is_pos).sum(), 1)
  return np.r_[0.0, fpr], np.r_[0.0, tpr]


def read_cluster(path) -> np.ndarray:
  return clean.clean_cloud(io.read_cloud(path), str(path))


def center_keypoint_distance(cluster: np.ndarray) -> float:
  """Distance (m) from the cluster's center (origin) to its nearest ISS keypoint; inf
  when ISS finds none."""
  idx = keypoints.iss(cluster)
  if len(idx) == 0:
    return float('inf')
  return float(np.min(np.linalg.norm(cluster[idx].astype(np.float64), axis=1)))


def fpfh_at_center(cluster: np.ndarray, radius: float = RADIUS,
                   max_nn: int = features_lib.FPFH_MAX_NN) -> np.ndarray:
  """FPFH [33] at the cluster's center: the origin is added as a point so the
  descriptor sits exactly at the keypoint, with normals estimated within `radius`."""
  points = np.concatenate([cluster, np.zeros((1, 3), cluster.dtype)])
  return features_lib.fpfh(points, np.array([len(cluster)]), radius=radius, max_nn=max_nn)[0]


def describe_pairs(pairs: Sequence[clusters_lib.ClusterPair], descriptors: Mapping,
                   radius: float = RADIUS, fpfh_max_nn: int = features_lib.FPFH_MAX_NN,
                   block: int = 500, progress: bool = True):
  """Descriptor distances of every pair and the ISS center distances of its clusters.

  descriptors: {name: None for 'fpfh', else an inference.Model}. Learned
  descriptors use the model's own (trained) radius. Clusters are read `block`
  pairs at a time; over several processes each describes its share of the blocks
  (`distributed.map_items`), gathered. -> ({name: [P] distances}, [P, 2] ISS center
  distances).
  """
  def describe_block(n, part) -> tuple[dict[str, np.ndarray], list]:
    c0 = [read_cluster(p.cluster0) for p in part]
    c1 = [read_cluster(p.cluster1) for p in part]
    iss = [[center_keypoint_distance(a), center_keypoint_distance(b)] for a, b in zip(c0, c1)]
    dist = {}
    for name, model in descriptors.items():
      if model is None:
        d0 = np.stack([fpfh_at_center(c, radius, fpfh_max_nn) for c in c0])
        d1 = np.stack([fpfh_at_center(c, radius, fpfh_max_nn) for c in c1])
      else:
        d0, d1 = inference.describe_clusters(model, c0), inference.describe_clusters(model, c1)
      dist[name] = np.linalg.norm(d0.astype(np.float64) - d1, axis=1)
    return dist, iss

  blocks = [pairs[start:start + block] for start in range(0, len(pairs), block)]
  per_block = distributed.map_items(
      describe_block, blocks, lambda ns: tqdm.tqdm(ns, desc='descriptor matching',
                                                  unit=f'block of {block}', disable=not progress))
  return ({name: np.concatenate([d[name] for d, _ in per_block]) for name in descriptors},
          np.asarray([r for _, iss in per_block for r in iss], np.float64).reshape(-1, 2))


def filtered_results(distances: Mapping[str, np.ndarray], labels: np.ndarray,
                     iss_distance: np.ndarray, r_th: Sequence[float] = R_TH,
                     recall: float = RECALL):
  """FPR at `recall` on all pairs and on the ISS-filtered subsets.

  -> [(r_th or None for all pairs, (positives, negatives), {name: FPR})].
  """
  labels = np.asarray(labels)
  out = []
  for r in (None, *r_th):
    keep = (np.ones(len(labels), bool) if r is None
            else np.all(np.asarray(iss_distance) <= r, axis=1))
    counts = (int(np.sum(labels[keep] == 1)), int(np.sum(labels[keep] == 0)))
    out.append((r, counts, {name: fpr_at_recall(d[keep], labels[keep], recall)[0]
                            for name, d in distances.items()}))
  return out


def save_distances(path, labels, distances: Mapping[str, np.ndarray],
                   iss_distance: np.ndarray) -> None:
  """The per-pair numbers behind the table, to re-threshold without recomputing."""
  np.savez(path, labels=np.asarray(labels), iss_distance=np.asarray(iss_distance),
           **{f'distance_{name}': d for name, d in distances.items()})
