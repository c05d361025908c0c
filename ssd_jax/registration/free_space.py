"""Free-space consistency: under a right pose, no point of one scan lies where the other
scan's laser passed through.

Along each ray of a scan in its sensor's frame, the space between the sensor and its
first return is empty. Under a right pose a point of scan 2 may lie beyond what scan 1
saw in its direction (occluded, or out of range), never well in front of it. A wrong pose
that still lays the ground and some structure on scan 1 puts scan 2's walls and poles in
scan 1's empty space: the classical check that tells such a pose from a right one where
fitness alone cannot (Huber and Hebert's visibility consistency, IVC 2003).

Each scan is binned by direction from its sensor (`range_image`: the nearest return per
AZIMUTH_STEP_DEG x ELEVATION_STEP_DEG cell, so that a cell holding a near and a far
return never calls a point in between a conflict). A point of the other scan in a seen
cell conflicts when the cell's nearest return lies more than `margin(range)` beyond it.
`conflict` is the larger share of the two directions; only for scans in their sensors'
frames (`sensor_centred`).

A surface is seen from one side: a laser's return lies on the face turned to its sensor.
Under a right pose the two sensors see a shared wall from the same side; a wrong pose
that lays a scan's wall on the other scan's wall seen from its back (the two sensors on
opposite sides of it, e.g. a place revisited from the other heading, laid on a wall of
the street across) has every return of it facing away from one sensor. `seen_from_behind`
is the share of the structure points lying on the other scan's surface (within the fit
distance) whose surface the two sensors face from opposite sides: free space cannot see
this wrong pose, as the wall's back lies beyond what the other scan saw.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np

from ssd_jax.data import preprocess
from ssd_jax.registration import icp

AZIMUTH_STEP_DEG = 1.0
ELEVATION_STEP_DEG = 1.0
# Metres: a point conflicts when the ray through it went on at least this much farther,
# plus RELATIVE_MARGIN of its range (the cell's angular width at range r is r * 0.017 m,
# and a pose 1-2 m or a few degrees off, still counted right, moves far points by more).
MARGIN = 1.0
RELATIVE_MARGIN = 0.1
# Points tested per direction (an even stride over the scan's structure).
TEST_POINTS = 4000
# Metres: a scan's own points nearer its sensor than this are not used (the vehicle).
MIN_RANGE = 1.0
# Metres: points nearer the judging sensor than this are not judged: people and cars that
# moved between the scans fill the space near a sensor (on a hand-held unit indoors, 5-20 %
# of a right pose's points within 3 m conflicted, none beyond).
MIN_JUDGED_RANGE = 3.0
# A scan in its sensor's frame has next to no points within BLIND_RADIUS metres of the
# sensor's vertical axis (the vehicle, the sensor's own blind zone): at most
# MAX_BLIND_SHARE of them, or, where a forward-looking unit is pitched down (a hand-held
# solid-state unit: 1-8 % of its points), ONE_SIDED_SHARE of them within
# ONE_SIDED_SPREAD_DEG of their mean azimuth: the ground ahead of it, in its view. A map
# tile, a submap or a cloud centred on its points has its ground all round there, and its
# origin is no viewpoint to judge free space from.
BLIND_RADIUS = 1.0
MAX_BLIND_SHARE = 0.005
ONE_SIDED_SPREAD_DEG = 60.0
ONE_SIDED_SHARE = 0.95
# Metres: a scan's median horizontal range is under this (a cloud in map coordinates, its
# origin kilometres away, has no points near the origin either).
MAX_MEDIAN_RANGE = 200.0
# Where the verification picks among its candidates (`ranked`): fitness less this many times
# the conflict. Far apart along a street a wrong pose can lay more of cloud 2 on cloud 1
# than the right one (the ground and the walls' lower parts overlap at any shift along
# it: 0.33 against 0.15-0.26 on the development drives' failures 20-30 m apart) while it
# puts 18-29 % of the structure in the other scan's empty space, where the right pose puts
# 3-8 %.
CONFLICT_WEIGHT = 2.0
# A point is judged for the side it is seen from where both sensors face its surface at
# an angle: |cos| between the surface normal and the direction to each sensor over this
# (a surface seen edge-on, the ground from far away, has no side to tell).
MIN_FACING_COS = 0.2
# Fewer judged points than this in a direction: no side is told (0).
MIN_FACING_POINTS = 50


@dataclasses.dataclass(frozen=True)
class RangeImage:
  """The nearest return per direction cell of one scan, sensor at the origin."""
  nearest: np.ndarray     # [elevation cells, azimuth cells] metres; inf where no return
  max_range: float        # metres: the farthest return

  def cells(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """points [M, 3] in the sensor's frame -> (elevation cell [M], azimuth cell [M],
    range [M] metres)."""
    r = np.linalg.norm(points, axis=1)
    azimuth = np.degrees(np.arctan2(points[:, 1], points[:, 0])) + 180.0
    elevation = np.degrees(np.arcsin(np.clip(points[:, 2] / np.maximum(r, 1e-9), -1, 1))) + 90.0
    a = np.minimum((azimuth / AZIMUTH_STEP_DEG).astype(int), self.nearest.shape[1] - 1)
    e = np.minimum((elevation / ELEVATION_STEP_DEG).astype(int), self.nearest.shape[0] - 1)
    return e, a, r


def range_image(points: np.ndarray) -> RangeImage:
  """A scan's `RangeImage`: points [N, 3] metres in its sensor's frame."""
  points = np.asarray(points, np.float64)
  shape = (int(round(180 / ELEVATION_STEP_DEG)), int(round(360 / AZIMUTH_STEP_DEG)))
  empty = RangeImage(np.full(shape, np.inf), 0.0)
  e, a, r = empty.cells(points)
  keep = r >= MIN_RANGE
  nearest = empty.nearest.copy()
  np.minimum.at(nearest, (e[keep], a[keep]), r[keep])
  return RangeImage(nearest, float(r[keep].max()) if keep.any() else 0.0)


def margin(r: np.ndarray) -> np.ndarray:
  """Metres a ray must pass beyond a point at range r [M] for the point to conflict."""
  return MARGIN + RELATIVE_MARGIN * r


def conflicts(image: RangeImage, points: np.ndarray) -> tuple[int, int]:
  """points [M, 3] in the image's sensor frame -> (how many lie in its empty space, how
  many lie in cells it saw, nearer than its farthest return: the ones it could judge)."""
  if not len(points):
    return 0, 0
  e, a, r = image.cells(points)
  seen = image.nearest[e, a]
  judged = np.isfinite(seen) & (r >= MIN_JUDGED_RANGE) & (r < image.max_range)
  conflict = judged & (seen > r + margin(r))
  return int(conflict.sum()), int(judged.sum())


def sensor_centred(points: np.ndarray) -> bool:
  """Whether a cloud [N, 3] metres looks like a scan in its sensor's frame (above)."""
  points = np.asarray(points)
  if not len(points):
    return False
  horizontal = np.linalg.norm(points[:, :2], axis=1)
  near = points[horizontal < BLIND_RADIUS]
  if len(near) > MAX_BLIND_SHARE * len(points):
    azimuth = np.arctan2(near[:, 1], near[:, 0])
    mean = np.arctan2(np.sin(azimuth).mean(), np.cos(azimuth).mean())
    off = np.abs(np.angle(np.exp(1j * (azimuth - mean))))
    if np.mean(off <= np.radians(ONE_SIDED_SPREAD_DEG)) < ONE_SIDED_SHARE:
      return False
  return bool(np.median(horizontal) < MAX_MEDIAN_RANGE)


def ranked(fitness, conflict: Callable[[int], float | None],
           refused: Callable[[int], bool] | None = None) -> np.ndarray:
  """Candidates (fitness [k]) best first, as the verification picks them: by fitness less
  CONFLICT_WEIGHT times their conflict (`conflict(c)`, None where free space cannot be
  judged: then by fitness alone). Ties keep the earlier candidate first. With `refused`,
  the first in that order for which `refused(c)` is False comes first (asked from the
  top, only as far as needed; the order stands where every candidate is refused)."""
  scores = np.asarray(fitness, np.float64).copy()
  for c in range(len(scores)):
    share = conflict(c)
    if share is None:
      scores = np.asarray(fitness, np.float64)
      break
    scores[c] -= CONFLICT_WEIGHT * share
  order = np.argsort(-scores, kind='stable')
  if refused is not None:
    first = next((n for n, c in enumerate(order) if not refused(c)), 0)
    order = np.concatenate([order[first:first + 1], order[:first], order[first + 1:]])
  return order


def _both_ways(of1, of2, points1: np.ndarray, points2: np.ndarray, transform: np.ndarray):
  """Both directions of a pair under T_12: (what is judged against, scan 1's `of1` then
  scan 2's `of2`; the other scan's points [M, 3], an even stride of TEST_POINTS, moved
  into its frame; the moved scan's pose in that frame [4, 4])."""
  t = np.asarray(transform, np.float64)
  for judge, pts, pose in ((of1, points2, t), (of2, points1, np.linalg.inv(t))):
    pts = np.asarray(pts, np.float64)[::preprocess.even_stride(len(pts), TEST_POINTS)]
    yield judge, pts @ pose[:3, :3].T + pose[:3, 3], pose


def conflict(image1: RangeImage, image2: RangeImage, points1: np.ndarray, points2: np.ndarray,
             transform: np.ndarray) -> float:
  """The larger share, over both directions, of one scan's points [M, 3] (its structure,
  in its sensor's frame) that lie in the other's empty space under T_12 (maps scan 2
  into scan 1's frame); 0 where neither scan could judge any."""
  shares = []
  for image, moved, _ in _both_ways(image1, image2, points1, points2, transform):
    bad, judged = conflicts(image, moved)
    shares.append(bad / judged if judged else 0.0)
  return float(max(shares))


def seen_from_behind(target1: icp.Surface, target2: icp.Surface, points1: np.ndarray,
                     points2: np.ndarray, transform: np.ndarray, distance: float) -> float:
  """The larger share, over both directions, of one scan's points [M, 3] (its structure,
  in its sensor's frame) lying within `distance` metres of the other scan's surface
  (target1, target2: each scan's `icp.Surface`) whose surface the two sensors (each at
  its frame's origin, placed by T_12 [4, 4]) face from opposite sides; judged where both
  face it at |cos| > MIN_FACING_COS; 0 where fewer than MIN_FACING_POINTS are judged."""
  shares = [0.0]
  for target, moved, pose in _both_ways(target1, target2, points1, points2, transform):
    dist, idx = target.tree.query(moved, distance_upper_bound=distance)
    idx = idx[np.isfinite(dist)]
    q, n = target.points[idx], target.normals_at(idx)
    cos = []
    for sensor in (np.zeros(3), pose[:3, 3]):   # the target's sensor, the moved scan's
      ray = sensor - q
      cos.append(np.einsum('ij,ij->i', n, ray) / np.maximum(np.linalg.norm(ray, axis=1), 1e-9))
    judged = (np.abs(cos[0]) > MIN_FACING_COS) & (np.abs(cos[1]) > MIN_FACING_COS)
    if judged.sum() >= MIN_FACING_POINTS:
      shares.append(float(np.mean(cos[0][judged] * cos[1][judged] < 0)))
  return max(shares)
