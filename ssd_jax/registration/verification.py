"""Hypothesis verification: which of RANSAC's candidate poses the clouds themselves agree
with.

RANSAC ranks a pose by how many putative correspondences it explains. Where the matches
are few and the scene repeats (a straight street of like objects, two scans tens of
metres apart), a wrong pose can explain as many as the right one, and the right one is
often among the runners-up (`ransac.distinct_best`). Candidates may also come from the
whole scene (`bev.search`). Each that could win is refined by point-to-plane ICP (`icp`),
coarse to fine, and scored by the share of cloud 2's structure (what rises from the
ground) it lays within `FIT_DISTANCE` of cloud 1: the dense geometry, not the sparse
matches, picks the pose: the check of a classic registration pipeline's verification step.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np

from ssd_jax.data import preprocess
from ssd_jax.registration import bev, icp, ransac

# Metres: a cloud-2 point this close to cloud 1 after a candidate's ICP counts as fitting
# (1.5 voxels of the 0.2 m grid: the two grids' offset and the sensors' noise).
FIT_DISTANCE = 0.3
# Cloud-2 points scored and aligned per candidate: an even stride over the cloud.
SOURCE_POINTS = 5000
# Cloud-1 points ICP aligns to, at most (an even stride over a denser cloud): its normals
# are the verification's largest cost, ~10 s for a map tile's 1.5 M grid points. Every
# cloud of the project's test sets (<= 46,000 points) is used whole.
TARGET_POINTS = 400_000
# What a candidate is scored on: the ground fits every upright pose that keeps it level,
# and covers most of a scan; only what rises from it (walls, poles, cars) tells a pose
# from one shifted along a street ('rising'). A cloud with fewer such points than
# MIN_RISING_POINTS (a bare field) is scored on all of them ('all').
SCORE_ON = 'rising'
MIN_RISING_POINTS = 200
# ICP of each candidate: correspondences within these distances (metres), in turn.
ICP_DISTANCES = (1.0, 0.5)
ICP_ITERATIONS = 30
# Coarse to fine: every candidate that could win is first aligned by COARSE_ITERATIONS
# steps of ICP at ICP_DISTANCES[0] with COARSE_POINTS of cloud 2's points; the
# FINE_CANDIDATES best of those (distinct poses, within FINE_MARGIN of the best's
# fitness) are then refined as above, from there.
COARSE_POINTS = 1000
COARSE_ITERATIONS = 10
FINE_CANDIDATES = 2
FINE_MARGIN = 0.1
# Metres: before any ICP, each candidate is scored by the share of cloud 2's scored points
# within this distance of cloud 1. One whose share at this distance does not exceed the
# best coarse-aligned candidate's share at FIT_DISTANCE is not aligned: ICP with 1 m
# correspondences moves a pose by less than this margin beyond its first distance, so it
# could not overtake (docs/registration.md: the register defaults' candidates).
PRESCORE_DISTANCE = 1.5
# A candidate whose start lies this close (metres, degrees) to a pose the coarse ICP has
# already started from or converged to shares that result: RANSAC's and the BEV search's
# poses of the right answer are often a cell or a yaw step apart.
SAME_START = (0.5, 1.0)
# A pose that lays at least this share of cloud 2's structure within FIT_DISTANCE of cloud 1
# is taken without looking further (`pair_stages.verify` skips the BEV search's candidates):
# no wrong pose of the project's sets came near it (RANSAC's best wrong ones fit <= 0.33),
# and where RANSAC's best fits this well the BEV search never changed the outcome
# (docs/registration.md: the register defaults' candidates).
CONFIDENT_FITNESS = 0.5
# A pose that ends the search early (`pair_stages.coarse_to_fine`'s coarse level) must be
# confident and clearly best: no candidate ransac.CANDIDATE_SEPARATION from it fits within
# FINE_MARGIN of it (a real 120-degree re-scan's coarse level verified a pose 1.8 m off at
# 0.82 beside a distinct one at 0.76).


def clearly_confident(poses: np.ndarray, fitness: np.ndarray,
                      min_fitness: float | None = None) -> bool:
  """Whether the best of verified poses [k, 4, 4] (fitness [k], `verify`) fits at least
  `min_fitness` (default CONFIDENT_FITNESS) with no distinct pose within FINE_MARGIN of
  it."""
  min_fitness = CONFIDENT_FITNESS if min_fitness is None else min_fitness
  order = ransac.distinct_best(poses, fitness, 2)
  best = fitness[order[0]]
  return bool(best >= min_fitness
              and (len(order) < 2 or fitness[order[1]] < best - FINE_MARGIN))


# Where only a confident pose is of use (`pair_stages.coarse_to_fine`'s coarse level; RANSAC's
# candidates before the BEV search's join them), the candidates are not refined in full
# when the best coarse-aligned one fits under CONFIDENT_FITNESS - UNREFINED_MARGIN: the
# full ICP raised a pose's fitness by at most 0.07 over its coarse alignment on the
# synthetic cross-sensor pairs.
UNREFINED_MARGIN = 0.15


@dataclasses.dataclass(frozen=True)
class Source:
  """Cloud 2 as verification moves it, made once per cloud: SOURCE_POINTS and
  COARSE_POINTS of its points for ICP, and the points a candidate is scored on."""
  points: np.ndarray       # [<= SOURCE_POINTS, 3] metres
  coarse: np.ndarray       # [<= COARSE_POINTS, 3]
  scored: np.ndarray       # [S, 3]


def target(points: np.ndarray) -> icp.Surface:
  """points [N, 3] metres -> cloud 1 as verification aligns to it (`icp.surface`), over
  at most TARGET_POINTS of its points (an even stride)."""
  points = np.asarray(points, np.float64)
  return icp.surface(points[::preprocess.even_stride(len(points), TARGET_POINTS)])


def source(points: np.ndarray, score_on: str = SCORE_ON) -> Source:
  """points [N, 3] metres, z up -> the `Source` of cloud 2, scored on what rises from
  its ground ('rising'; all of its points where fewer than MIN_RISING_POINTS rise) or on
  all of its points ('all')."""
  if score_on not in ('rising', 'all'):
    raise ValueError(f"score_on must be 'rising' or 'all', got {score_on!r}")
  points = np.asarray(points, np.float64)
  icp_points = _even(points, SOURCE_POINTS)
  scored = icp_points
  if score_on == 'rising':
    rising = points[bev.rising_from_ground(points)]
    if len(rising) >= MIN_RISING_POINTS:
      scored = _even(rising, SOURCE_POINTS)
  coarse = points[::preprocess.even_stride(len(points), COARSE_POINTS)]
  return Source(icp_points, np.ascontiguousarray(coarse), np.ascontiguousarray(scored))


def _even(points: np.ndarray, count: int) -> np.ndarray:
  return np.ascontiguousarray(points[::max(1, len(points) // count)])


def fitness(target: icp.Surface, points: np.ndarray, transform: np.ndarray,
            distance: float = FIT_DISTANCE) -> float:
  """Share of points [S, 3] within `distance` metres of the target after T_12 (Open3D's
  `evaluate_registration` fitness)."""
  if not len(points):
    return 0.0
  found, _, _ = icp.correspondences(target, points @ transform[:3, :3].T + transform[:3, 3],
                                    distance)
  return float(found.mean())


def _close(a: np.ndarray, b: np.ndarray, limits: tuple[float, float]) -> bool:
  cos = (np.trace(a[:3, :3] @ b[:3, :3].T) - 1.0) / 2.0
  return bool(np.linalg.norm(a[:3, 3] - b[:3, 3]) < limits[0]
              and cos > np.cos(np.deg2rad(limits[1])))


def verify(points1, points2, candidates: np.ndarray, score_on: str = SCORE_ON,
           memo: dict | None = None, confident_only: bool = False,
           choose: Callable[[np.ndarray, np.ndarray], int] | None = None,
           robust: bool = False) -> tuple[int, np.ndarray, np.ndarray]:
  """Candidate poses T_12 [k, 4, 4] of cloud 2 in cloud 1 (points [N, 3] metres near the
  origin, z up, or their `target` and `source`) -> (index of the best, each candidate
  refined by ICP [k, 4, 4], their fitness [k]: the share of cloud 2's points that rise
  from the ground (`score_on` 'rising'; 'all': of all its points) within FIT_DISTANCE of
  cloud 1). Coarse to fine: candidates that could win (`PRESCORE_DISTANCE`) are aligned
  by a coarse ICP, best pre-score first; the FINE_CANDIDATES best of those are refined in
  full. A candidate that could not overtake keeps its pose and its fitness there; the
  fitness of one aligned only coarsely is its coarse one. Ties keep the earlier
  candidate (RANSAC's order). Deterministic. `memo`: a dict shared by calls on the same
  pair of clouds (e.g. RANSAC's candidates, then those and the BEV search's), in which
  each ICP and fitness is kept under its start pose, so that no call repeats one. With
  `confident_only`, where no coarse-aligned candidate fits within UNREFINED_MARGIN of
  CONFIDENT_FITNESS, none is refined in full (each keeps its coarse pose and fitness).
  `choose(poses [k, 4, 4], fitness [k]) -> index` picks the answer (default: the best
  fitness; e.g. the first of `free_space.ranked` instead); whichever it picks is refined
  in full, and picked again from there. `robust`: every ICP with the robust kernel
  (`icp.point_to_plane`), kept in `memo` apart from the plain ones."""
  tgt = points1 if isinstance(points1, icp.Surface) else target(points1)
  if isinstance(points2, Source):
    if score_on != SCORE_ON:
      raise ValueError('score_on is chosen when the Source is made (verification.source)')
    src = points2
  else:
    src = source(points2, score_on)
  candidates = np.asarray(candidates, np.float64)
  memo = {} if memo is None else memo

  def kept(kind, transform, compute):   # pure functions of the pose for one pair of clouds
    key = (kind, transform.tobytes())
    if key not in memo:
      memo[key] = compute()
    return memo[key]

  score = lambda t: kept('fit', t, lambda: fitness(tgt, src.scored, t))
  prescore = np.array([kept('prescore', t, lambda t=t: fitness(tgt, src.scored, t,
                                                               PRESCORE_DISTANCE))
                       for t in candidates])
  refined = candidates.copy()
  scores = np.full(len(candidates), -1.0)
  aligned = []   # candidates the coarse ICP aligned
  for c in np.argsort(-prescore, kind='stable'):
    twin = next((d for d in aligned if _close(candidates[c], candidates[d], SAME_START)
                 or _close(candidates[c], refined[d], SAME_START)), None)
    if twin is not None:
      refined[c], scores[c] = refined[twin], scores[twin]
    elif aligned and prescore[c] <= scores.max():
      scores[c] = score(candidates[c])
    else:
      refined[c] = kept(('coarse', robust), candidates[c], lambda c=c: icp.point_to_plane(
          tgt, src.coarse, candidates[c], ICP_DISTANCES[:1], COARSE_ITERATIONS,
          robust=robust)[0])
      scores[c] = score(refined[c])
      aligned.append(c)
  if confident_only and scores.max() < CONFIDENT_FITNESS - UNREFINED_MARGIN:
    return int(np.argmax(scores)), refined, scores
  fine = set()

  def refine(c):   # in full, with every candidate that shares its coarse result
    t = kept(('fine', robust), refined[c], lambda: icp.point_to_plane(
        tgt, src.points, refined[c], ICP_DISTANCES, ICP_ITERATIONS, robust=robust)[0])
    fit = score(t)
    for d in np.flatnonzero(np.all(refined == refined[c], axis=(1, 2))):
      refined[d], scores[d] = t, fit
      fine.add(int(d))

  for c in ransac.distinct_best(refined, scores, FINE_CANDIDATES, SAME_START):
    if scores[c] >= scores.max() - FINE_MARGIN and c not in fine:
      refine(c)
  # The answer is refined in full: a coarse-only pose that is picked is refined too (a
  # coarse ICP can stop a few degrees off where the full one reaches the pose).
  choose = (lambda poses, fit: int(np.argmax(fit))) if choose is None else choose
  while (best := choose(refined, scores)) not in fine:
    refine(best)
  return best, refined, scores
