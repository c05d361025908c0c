"""Putative correspondences from descriptors (docs/method.md §4)."""

from __future__ import annotations

import numpy as np
from scipy import spatial


def nearest_neighbour_matches(desc1: np.ndarray, desc2: np.ndarray) -> np.ndarray:
  """For every descriptor of cloud 1 [K1, D], its nearest (Euclidean) descriptor among
  cloud 2's [K2, D]. -> [K1] indices into desc2."""
  _, idx = spatial.cKDTree(desc2).query(desc1)
  return idx.astype(np.int64)
