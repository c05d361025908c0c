"""Putative correspondences from descriptors (docs/method.md §4)."""

from __future__ import annotations

import numpy as np
from scipy import spatial


def nearest_neighbour_matches(desc1: np.ndarray, desc2: np.ndarray) -> np.ndarray:
  """For every descriptor of cloud 1 [K1, D], its nearest (Euclidean) descriptor among
  cloud 2's [K2, D]. -> [K1] indices into desc2."""
  _, idx = spatial.cKDTree(desc2).query(desc1)
  return idx.astype(np.int64)


def both_ways_matches(desc1: np.ndarray, desc2: np.ndarray) -> np.ndarray:
  """Every descriptor's nearest among the other cloud's, both ways, each pair once:
  [C, 2] (index into desc1 [K1, D], index into desc2 [K2, D]), C <= K1 + K2, sorted.
  Cloud 2's nearest neighbours add correct matches that cloud 1's miss
  (docs/registration.md, compatible samples)."""
  forward = np.stack([np.arange(len(desc1)), nearest_neighbour_matches(desc1, desc2)], 1)
  backward = np.stack([nearest_neighbour_matches(desc2, desc1), np.arange(len(desc2))], 1)
  return np.unique(np.concatenate([forward, backward]), axis=0)
