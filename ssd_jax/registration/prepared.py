"""One cloud as the BEV search and the verification use it, each part made once.

In a batch a scan meets many others (consecutive scans, loop-closure candidates, the
pairs of an evaluation set): its footprint for the bird's-eye-view search, its normals
and KD-tree as the cloud aligned to, and its points as the cloud moved, are the same for
every pair, so `PreparedCloud` makes each on first use and keeps it.
"""

from __future__ import annotations

import functools

import numpy as np

from ssd_jax.registration import bev, icp, verification


class PreparedCloud:
  """points [N, 3] metres (float64, z up), with `footprint` (`bev.footprint`), `target`
  (`verification.target`: as cloud 1) and `source` (`verification.source`: as cloud 2)
  made on first use."""

  def __init__(self, points: np.ndarray):
    self.points = np.asarray(points, np.float64)

  def __len__(self) -> int:
    return len(self.points)

  @functools.cached_property
  def footprint(self) -> bev.Footprint:
    return bev.footprint(self.points)

  @functools.cached_property
  def target(self) -> icp.Surface:
    return verification.target(self.points)

  @functools.cached_property
  def source(self) -> verification.Source:
    return verification.source(self.points)


def prepare(points) -> PreparedCloud:
  """points [N, 3] or a `PreparedCloud` (returned as it is)."""
  return points if isinstance(points, PreparedCloud) else PreparedCloud(points)
