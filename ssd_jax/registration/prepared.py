"""One cloud, and one pair, as the BEV search and the verification use them, each part
made once.

In a batch a scan meets many others (consecutive scans, loop-closure candidates, the
pairs of an evaluation set): its footprint for the bird's-eye-view search, its normals
and KD-tree as the cloud aligned to, and its points as the cloud moved, are the same for
every pair, so `PreparedCloud` makes each on first use and keeps it. A pair registered
more than once (coarse to fine, or several methods of an evaluation on one pair) has the
same BEV search poses and the same ICP from each start pose every time: `PreparedPair`
keeps those.
"""

from __future__ import annotations

import functools

import numpy as np

from ssd_jax.registration import bev, free_space, icp, verification


class PreparedCloud:
  """points [N, 3] metres (float64, z up), with `footprint` (`bev.footprint`), `target`
  (`verification.target`: as cloud 1), `source` (`verification.source`: as cloud 2) and
  `range_image` (`free_space`) made on first use. viewpoint False: the origin is not the
  cloud's sensor, whatever the cloud looks like (no range image)."""

  def __init__(self, points: np.ndarray, viewpoint: bool = True):
    self.points = np.asarray(points, np.float64)
    self.viewpoint = viewpoint

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

  @functools.cached_property
  def range_image(self) -> free_space.RangeImage | None:
    """Its nearest return per direction (`free_space.range_image`), None where it is no
    scan in its sensor's frame (`viewpoint` False, or `free_space.sensor_centred`)."""
    if not (self.viewpoint and free_space.sensor_centred(self.points)):
      return None
    return free_space.range_image(self.points)


def prepare(points) -> PreparedCloud:
  """points [N, 3] or a `PreparedCloud` (returned as it is)."""
  return points if isinstance(points, PreparedCloud) else PreparedCloud(points)


# The banded BEV search's distinct poses `PreparedPair.bev_poses` ranks before it keeps
# its k: on a narrow unit's far pairs the correlation ranks the right pose 10th-40th, where
# its structure's share near cloud 1 less the conflict ranks it among the first three
# (docs/notes/real_drives.md). Not the first try's ranking: a coarse pose of a sparse
# unit's scan can conflict 25 %, and the right one drops out.
BEV_POOL = 50


class PreparedPair:
  """Cloud 1 (the target) and cloud 2 (the source, moved onto it) as `PreparedCloud`s,
  with `memo`, what is made of the two together: the verification's ICP and fitness per
  start pose (`verification.verify`) and the BEV search's poses (`bev_poses`). A memo
  holds poses and numbers only, so a caller may keep it for the pair (and pass it in
  again) after the clouds themselves are gone."""

  def __init__(self, cloud1, cloud2, memo: dict | None = None):
    self.cloud1, self.cloud2 = prepare(cloud1), prepare(cloud2)
    self.memo = {} if memo is None else memo

  def conflict(self, transform: np.ndarray) -> float | None:
    """`free_space.conflict` of the clouds' structure under T_12, kept per pose; None
    where either cloud is no scan in its sensor's frame."""
    return self._seen('conflict', transform, lambda: free_space.conflict(
        self.cloud1.range_image, self.cloud2.range_image, self.cloud1.source.scored,
        self.cloud2.source.scored, transform))

  def behind(self, transform: np.ndarray) -> float | None:
    """`free_space.seen_from_behind` of the clouds' structure under T_12 (within
    `verification.FIT_DISTANCE`), kept per pose; None where either cloud is no scan in
    its sensor's frame."""
    return self._seen('behind', transform, lambda: free_space.seen_from_behind(
        self.cloud1.target, self.cloud2.target, self.cloud1.source.scored,
        self.cloud2.source.scored, transform, verification.FIT_DISTANCE))

  def _seen(self, name: str, transform: np.ndarray, measure) -> float | None:
    """What the two sensors' viewpoints tell of T_12 (`measure()`), kept per pose; None
    where either cloud is no scan in its sensor's frame (its origin no viewpoint)."""
    if self.cloud1.range_image is None or self.cloud2.range_image is None:
      return None
    key = (name, np.asarray(transform, np.float64).tobytes())
    if key not in self.memo:
      self.memo[key] = measure()
    return self.memo[key]

  def bev_poses(self, k: int, banded: bool = False) -> np.ndarray:
    """The k best T_12 [k, 4, 4] of `bev.search` on the two footprints; `banded`: the k
    first of its banded search's BEV_POOL best, ranked as the verification picks
    (`free_space.ranked`: the share of cloud 2's structure within
    `verification.PRESCORE_DISTANCE` of cloud 1 less the conflict)."""
    key = ('bev', k, banded)
    if key not in self.memo:
      f1, f2 = self.cloud1.footprint, self.cloud2.footprint
      if not banded:
        self.memo[key] = bev.search(f1, f2, k).transforms
      else:
        poses = bev.search(f1, f2, max(k, BEV_POOL), banded=True).transforms
        near = [verification.fitness(self.cloud1.target, self.cloud2.source.scored, t,
                                     verification.PRESCORE_DISTANCE) for t in poses]
        self.memo[key] = poses[free_space.ranked(near, lambda c: self.conflict(poses[c]))[:k]]
    return self.memo[key]


def prepare_pair(points1, points2) -> PreparedPair:
  """A `PreparedPair` of points1 (cloud 1) and points2 (cloud 2) [N, 3] or
  `PreparedCloud`s; a `PreparedPair` as points1 (points2 None) is returned as it is."""
  if isinstance(points1, PreparedPair):
    if points2 is not None:
      raise ValueError('a PreparedPair already holds cloud 2')
    return points1
  return PreparedPair(points1, points2)
