"""The stages of one pair, as in Open3D's registration pipeline: descriptor matches and
RANSAC (`estimate`), the candidate poses checked against the clouds (`verify`), both from
coarse keypoints first (`coarse_to_fine`), ICP (`refine_icp`), the pose's assessment
(`assess`: its uncertainty and verdict) and a trusted pose's robust refinement (`polish`).
Each takes the clouds' features (`cloud_features`) so that an evaluation can cache them and
only match and estimate per pair."""

from __future__ import annotations

import dataclasses
import time
from typing import Callable, Sequence

import numpy as np
from scipy import spatial

from ssd_jax.registration import cloud_features, free_space, icp, matching, prepared, ransac
from ssd_jax.registration import options as options_lib
from ssd_jax.registration import uncertainty as uncertainty_lib, verification
from ssd_jax.registration import verdict as verdict_lib

Features = cloud_features.CloudFeatures

@dataclasses.dataclass
class Registration:
  transform: np.ndarray    # [4, 4] T_12: maps cloud 2 into cloud 1's frame
  matches: np.ndarray      # [C, 2] (keypoint of cloud 1, matched keypoint of cloud 2)
  inliers: np.ndarray      # [C] bool
  trials: int
  seconds: dict
  icp_fitness: float | None = None   # share of cloud-2 points with an ICP partner
  notes: list = dataclasses.field(default_factory=list)   # fallbacks used, one line each
  # As Open3D's RegistrationResult, over the C matches under the final transform: the
  # share within the inlier threshold, their RMSE (metres) and their count.
  fitness: float = 0.0
  inlier_rmse: float = 0.0
  correspondence_set_size: int = 0
  candidates: np.ndarray | None = None   # [k, 4, 4] RANSAC's distinct best poses (`verify`)
  # After `verify`: per candidate, ICP-refined, the share of cloud 2's structure (what rises
  # from its ground; `verification.verify`) within FIT_DISTANCE of cloud 1. The transform
  # is the best of them.
  verified_fitness: np.ndarray | None = None
  verified_poses: np.ndarray | None = None   # [k, 4, 4] each candidate after its ICP
  # What the scans fix of the transform (`assess`): its information matrix and the
  # directions they leave free.
  uncertainty: uncertainty_lib.PoseUncertainty | None = None
  # Whether the transform is to be trusted, and why not (`assess`, `verdict`).
  verdict: verdict_lib.Verdict | None = None
  levels_tried: int = 1   # `coarse_to_fine`: keypoint levels it took (2: the coarse did not do)


def _match_stats(xyz1: np.ndarray, xyz2: np.ndarray, transform: np.ndarray,
                 inlier_threshold: float) -> tuple[np.ndarray, dict]:
  """Over matches xyz1[i] <-> xyz2[i] under T_12: (which are within the threshold [C],
  Open3D's RegistrationResult numbers)."""
  residual = np.linalg.norm(xyz2 @ transform[:3, :3].T + transform[:3, 3] - xyz1, axis=1)
  close = residual < inlier_threshold
  rmse = float(np.sqrt(np.mean(residual[close] ** 2))) if close.any() else 0.0
  return close, {'fitness': float(close.mean()), 'inlier_rmse': rmse,
                 'correspondence_set_size': int(close.sum())}


def estimate(f1: Features, f2: Features, seed: int = 0, inlier_threshold: float = 1.0,
             confidence: float = 0.99, max_trials: int = 10_000,
             estimator: str = 'rigid', candidates: int = 1,
             sampling: str = 'auto') -> Registration:
  """Descriptor matches, then RANSAC with the motion model `estimator` (`ESTIMATORS`):
  the rigid one over the nearest neighbours of cloud 1's keypoints among cloud 2's, the
  upright one as `sampling` says (`SAMPLINGS`). With `candidates` > 1 (upright only) the
  result keeps that many distinct best poses for `verify`."""
  if estimator not in options_lib.ESTIMATORS:
    raise ValueError(f'estimator must be one of {options_lib.ESTIMATORS}, got {estimator!r}')
  if sampling not in options_lib.SAMPLINGS:
    raise ValueError(f'sampling must be one of {options_lib.SAMPLINGS}, got {sampling!r}')
  if len(f1.xyz) < 3 or len(f2.xyz) < 3:
    raise ValueError(f'too few keypoints to register ({len(f1.xyz)} and {len(f2.xyz)}; at '
                     'least 3 each): is the cloud degenerate (empty, planar or collinear)?')
  t0 = time.perf_counter()
  if sampling == 'auto':
    sampling = 'compatible' if candidates <= 1 else 'uniform'
  compatible = estimator == 'upright' and sampling == 'compatible'
  if compatible:
    matches = matching.both_ways_matches(f1.descriptors, f2.descriptors)
  else:
    nn = matching.nearest_neighbour_matches(f1.descriptors, f2.descriptors)
    matches = np.stack([np.arange(len(nn)), nn], 1)
  xyz1 = f1.xyz[matches[:, 0]].astype(np.float64)
  xyz2 = f2.xyz[matches[:, 1]].astype(np.float64)
  t1 = time.perf_counter()
  rng = np.random.default_rng(seed)
  if compatible:
    samples, pairs = ransac.draw_compatible_samples(rng, xyz1, xyz2, max_trials + 1,
                                                    inlier_threshold)
    res = ransac.ransac_upright(xyz1, xyz2, samples, inlier_threshold, confidence, max_trials,
                               candidates=candidates, pairs=pairs)
  elif estimator == 'upright':
    samples = ransac.draw_upright_samples(rng, xyz2, max_trials + 1)
    res = ransac.ransac_upright(xyz1, xyz2, samples, inlier_threshold, confidence, max_trials,
                               candidates=candidates)
  else:
    samples = ransac.draw_minimal_samples(rng, xyz2, max_trials + 1)
    res = ransac.ransac(xyz1, xyz2, samples, inlier_threshold, confidence, max_trials)
  t2 = time.perf_counter()
  return Registration(res.transform, matches, res.inliers,
                      res.trials, {'matching': t1 - t0, 'ransac': t2 - t1},
                      candidates=res.candidates,
                      **_match_stats(xyz1, xyz2, res.transform, inlier_threshold)[1])


def verify(reg: Registration, f1: Features, f2: Features, points1, points2=None,
           inlier_threshold: float = 1.0, bev_candidates: int = 0,
           confident_only: bool = False, bev_banded: bool = False,
           robust: bool = False) -> Registration:
  """`reg` with the candidate pose (`estimate(candidates=k)`) that, refined by ICP, lays the
  most of cloud 2's structure on cloud 1 (`verification.verify`). points1, points2: the
  clouds [N, 3] (metres near the origin, in the features' coordinates) or their
  `prepared.PreparedCloud`s, which keep what is made of a cloud for its next pair; or
  points1 a `prepared.PreparedPair` (points2 None), which also keeps the BEV search's
  poses and every ICP for the pair's next registration. With `bev_candidates` b > 0
  (upright scans), unless RANSAC's best already lays `verification.CONFIDENT_FITNESS` of
  cloud 2's structure on cloud 1, the b best poses of the bird's-eye-view search
  (`bev.search`; `bev_banded`: and b of its banded search, ranked as the verification
  picks, `prepared.PreparedPair.bev_poses`) are checked too, after RANSAC's, all
  together. Inliers and the RegistrationResult numbers are recounted over the matches
  under the chosen pose; `verified_fitness` has one entry per candidate checked (k,
  k + b, or k + 2b); `seconds` gains
  'bev' (0 where it was not needed) and 'verify'. `confident_only`: only a pose fitting
  CONFIDENT_FITNESS is of use (no BEV search then): candidates far from it are not
  refined in full (`verification.verify`); so it is for RANSAC's candidates alone before
  the BEV search's join them. `robust`: the candidates aligned by the robust ICP
  (`verification.verify`)."""
  t0 = time.perf_counter()
  pair = prepared.prepare_pair(points1, points2)
  target, source = pair.cloud1.target, pair.cloud2.source
  candidates = reg.candidates if reg.candidates is not None else reg.transform[None]
  # With the BEV search to follow, RANSAC's candidates alone only decide whether it runs
  # (a confident pose), and the call with both refines what wins: none is refined in full
  # here unless it could be confident (`confident_only`).
  # Among them, the one that also leaves each scan's empty space empty (`free_space.ranked`)
  # and whose surfaces the two sensors do not face from opposite sides: the verdict refuses
  # such a pose (`verdict.seen_from_behind`), so one it would not refuse is taken first.
  choose = lambda poses, fit: int(free_space.ranked(
      fit, lambda c: pair.conflict(poses[c]),
      lambda c: verdict_lib.seen_from_behind(fit[c], pair.behind(poses[c])))[0])
  best, refined, fitness = verification.verify(target, source, candidates, memo=pair.memo,
                                               confident_only=confident_only or bev_candidates > 0,
                                               choose=choose, robust=robust)
  seconds = {**reg.seconds, 'verify': time.perf_counter() - t0}
  if bev_candidates > 0:
    seconds['bev'] = 0.0
    if fitness[best] < verification.CONFIDENT_FITNESS:
      t1 = time.perf_counter()
      # The banded poses join the first try's rather than replace them, so the verdict
      # sees a first pose that fits as well as a new one (`verdict.assess`: ambiguous).
      bev_poses = [pair.bev_poses(bev_candidates)]
      if bev_banded:
        bev_poses.append(pair.bev_poses(bev_candidates, banded=True))
      candidates = np.concatenate([candidates, *bev_poses])
      t2 = time.perf_counter()
      best, refined, fitness = verification.verify(target, source, candidates,
                                                   memo=pair.memo, choose=choose,
                                                   robust=robust)
      seconds['bev'] = t2 - t1
      seconds['verify'] += time.perf_counter() - t2
  xyz1 = f1.xyz[reg.matches[:, 0]].astype(np.float64)
  xyz2 = f2.xyz[reg.matches[:, 1]].astype(np.float64)
  inliers, stats = _match_stats(xyz1, xyz2, refined[best], inlier_threshold)
  return dataclasses.replace(reg, transform=refined[best], inliers=inliers, seconds=seconds,
                             verified_fitness=fitness, verified_poses=refined, **stats)


def coarse_to_fine(levels1: Sequence[Callable[[], Features]],
                   levels2: Sequence[Callable[[], Features]], points1, points2=None, *,
                   seed: int = 0, inlier_threshold: float = 1.0, confidence: float = 0.99,
                   max_trials: int = 10_000, estimator: str = 'upright', candidates: int = 10,
                   bev_candidates: int = 0, verified: bool = True, progress=None,
                   sampling: str = 'auto', bev_banded: bool = False, robust: bool = False
                   ) -> tuple[Registration, Features, Features]:
  """`estimate` (`candidates` poses) and, where `verified`, `verify` on each level of the
  two clouds' features in turn (callables, coarse first: `FeatureLevels.levels`), until a
  level's verified pose lays `verification.CONFIDENT_FITNESS` of cloud 2's structure on
  cloud 1 and no distinct candidate comes near it (`verification.clearly_confident`).
  The last level is the registration without levels, the BEV search's candidates
  included; the ones before only end it early (unverified, only the last level runs).
  points1, points2: as for `verify`; `progress(stage)` as for `register`, on the first
  level tried; `sampling` as for `estimate`, `bev_banded` and `robust` as for `verify`.
  -> (registration, features of cloud 1, of cloud 2) of the level that decided, its
  `seconds` summed over the levels tried and `levels_tried` set."""
  if not levels1 or len(levels1) != len(levels2):
    raise ValueError(f'the clouds have {len(levels1)} and {len(levels2)} feature levels')
  first = 0 if verified else len(levels1) - 1
  pair = prepared.prepare_pair(points1, points2)   # one memo over the levels
  stage = (lambda name: None) if progress is None else progress
  # 'bev' is 0 where an earlier level or RANSAC's confident pose made the search needless.
  spent: dict[str, float] = {'bev': 0.0} if verified and bev_candidates > 0 else {}
  for n in range(first, len(levels1)):
    last = n == len(levels1) - 1
    f1, f2 = levels1[n](), levels2[n]()
    if n == first:
      stage('RANSAC')
    reg = estimate(f1, f2, seed, inlier_threshold, confidence, max_trials, estimator,
                   candidates, sampling)
    if verified:
      if n == first:
        stage('verification')
      reg = verify(reg, f1, f2, pair, None, inlier_threshold, bev_candidates if last else 0,
                   confident_only=not last, bev_banded=bev_banded, robust=robust)
    for name, s in reg.seconds.items():
      spent[name] = spent.get(name, 0.0) + s
    if last or verification.clearly_confident(reg.verified_poses, reg.verified_fitness):
      return dataclasses.replace(reg, seconds=spent, levels_tried=n - first + 1), f1, f2


def assess(reg: Registration, points1, points2=None, origin: np.ndarray | None = None,
           min_constraint: float = uncertainty_lib.MIN_CONSTRAINT) -> Registration:
  """`reg` with its `uncertainty` at its transform (`uncertainty.assess`) and its
  `verdict` (`verdict.assess`): points1, points2 as for `verify` (free space is judged
  where both are scans from their origins, `prepared.PreparedCloud.range_image`);
  `origin` [3]: cloud 1's frame origin in their coordinates (default 0); `min_constraint`:
  what every shift must be held by, per correspondence, not to be called degenerate
  (`verdict.RETRY_MIN_CONSTRAINT` for a retry's pose). Uses the verification's candidates
  where `reg` was verified."""
  t0 = time.perf_counter()
  pair = prepared.prepare_pair(points1, points2)
  cloud1, cloud2 = pair.cloud1, pair.cloud2
  assessed = uncertainty_lib.assess(cloud1.target, cloud2.source.points, reg.transform,
                                    origin)
  judged = verdict_lib.assess(pair, reg.transform, assessed.free_under(min_constraint),
                              reg.verified_poses, reg.verified_fitness,
                              support=int(reg.inliers.sum()))
  return dataclasses.replace(reg, uncertainty=assessed, verdict=judged,
                             seconds={**reg.seconds, 'assess': time.perf_counter() - t0})


def polish(reg: Registration, points1, points2=None, origin: np.ndarray | None = None,
           min_constraint: float = uncertainty_lib.MIN_CONSTRAINT) -> Registration:
  """`reg`, whose verdict trusts its pose, with that pose refined by the robust ICP
  (`icp.point_to_plane`, robust, at the verification's distances and steps) and assessed
  again (`assess`, the same arguments), where the verdict still trusts it there; else `reg`
  as it is. The verification picks among poses its plain ICP aligned, which drags a right
  pose by the points two scans do not share (0.2-0.5 m and 1-4 degrees on a hand-held
  unit's pairs 10-20 m apart); the kernel lays it where what they share fits."""
  t0 = time.perf_counter()
  pair = prepared.prepare_pair(points1, points2)
  moved, _ = icp.point_to_plane(pair.cloud1.target, pair.cloud2.source.points,
                                reg.transform, verification.ICP_DISTANCES,
                                verification.ICP_ITERATIONS, robust=True)
  timed = {**reg.seconds, 'icp': reg.seconds.get('icp', 0.0) + time.perf_counter() - t0}
  again = assess(dataclasses.replace(reg, transform=moved, seconds=timed), pair, None,
                 origin, min_constraint)
  spent = {**again.seconds, 'assess': again.seconds['assess'] + reg.seconds['assess']}
  return dataclasses.replace(again if again.verdict.registered else reg, seconds=spent)


def refine_icp(points1: np.ndarray, points2: np.ndarray, transform: np.ndarray,
               max_distance: float = 1.0) -> tuple[np.ndarray, float]:
  """Point-to-plane ICP (`icp.point_to_plane`) from `transform`, at max_distance then half
  of it, 50 steps each. points1 is the target (normals within 1 m), points2 the source.
  -> (T_12, fitness in [0, 1]: share of cloud-2 points with a partner)."""
  return icp.point_to_plane(icp.surface(points1), points2, transform,
                            (max_distance, max_distance / 2), iterations=50)


def overlap_fitness(points1: np.ndarray, points2: np.ndarray, transform: np.ndarray,
                    max_distance: float = 0.5) -> float:
  """Fraction of cloud-2 points within max_distance of cloud 1 after T_12."""
  moved = np.asarray(points2, np.float64) @ transform[:3, :3].T + transform[:3, 3]
  dist, _ = spatial.cKDTree(points1).query(moved, distance_upper_bound=max_distance)
  return float(np.mean(np.isfinite(dist)))
