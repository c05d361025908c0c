"""Register two clouds: keypoints -> descriptors -> matches -> RANSAC (-> ICP).

Each stage is its own function, as in Open3D's registration pipeline, so an
evaluation can cache per-cloud keypoints and descriptors and only match and
estimate per pair.
"""

from __future__ import annotations

import collections
import dataclasses
import functools
import os
import time
from typing import Callable, Iterable, Iterator, Sequence

import numpy as np
from scipy import spatial

from ssd_jax import errors, inference
from ssd_jax.data import clean, preprocess
from ssd_jax.data.clean import check_cloud
from ssd_jax.registration import bev, features, free_space, icp, keypoints as keypoints_lib
from ssd_jax.registration import leveling
from ssd_jax.registration import matching
from ssd_jax.registration import prepared, ransac, uncertainty as uncertainty_lib, verification
from ssd_jax.registration import verdict as verdict_lib

KEYPOINTS = ('auto', 'iss', 'learned', 'random')
DESCRIPTORS = ('fpfh', 'learned')
# RANSAC's motion model: 'rigid', 3-point samples of any rotation (the paper's); 'upright',
# 2-point samples of a turn about z and a translation, for scans whose z axis is up,
# refit in 6 degrees of freedom (ransac.ransac_upright).
ESTIMATORS = ('rigid', 'upright')
# How the upright estimator takes its matches and samples (`estimate`): 'compatible', each
# keypoint's nearest descriptor both ways (`matching.both_ways_matches`) and 2-point samples
# drawn among the pairs of matches one turn about z and shift can fit
# (`ransac.compatible_pairs`); 'uniform', cloud 1's nearest neighbours and uniform draws
# (the paper's RANSAC with 2-point samples); 'auto', compatible where RANSAC's best pose is
# the answer, uniform where its distinct best poses are verified against the clouds.
# Compatible samples crowd into the strongest consensus: on a street that looks alike turned
# by 180 degrees its 10 distinct best poses can all be variants of the turned one, where
# uniform draws keep the right pose among them for the verification to pick
# (docs/registration.md). The rigid estimator always samples uniformly.
SAMPLINGS = ('auto', 'compatible', 'uniform')
# Whether each scan is first turned level by its ground (`Options.level`, `leveling`).
LEVELS = ('none', 'ground')
# Metres: the voxel grid of every set the shipped models were trained and tested on
# (3DFeat-Net's processing), and so the grid every cloud is put on before its features
# (`to_grid`) unless the model says otherwise (`inference.Model.voxel_size`).
VOXEL_SIZE = 0.2
# A cloud that keeps at least this share of its points on the grid is on such a grid
# already, used as given: re-gridding would only move its points by a fraction of a cell.
# Clouds voxelised at 0.2 m on another grid keep 0.69-1.0 (every test set here), raw
# 64-beam scans ~0.3, anything twice as dense as the grid under 0.3.
ON_GRID = 0.6


# How the learned descriptor samples each ball where the candidate poses are verified
# against the clouds (the register defaults): one draw of 32 points, as the shipped models
# trained. More points and draws steady the matches that RANSAC's best pose alone depends on
# (the shipped models' 4 draws of 64 points, for the paper's protocol); with the BEV search
# and the verification picking the pose, one draw of 32 registered every pair that four of
# 64 did on every set of the README's table, at an eighth of the network's work
# (docs/notes/benchmarks.md).
VERIFIED_DRAWS = 1
VERIFIED_SAMPLES = 32


def verified_model(model):
  """`model` (an `inference.Model`, or None) describing with VERIFIED_DRAWS samplings of
  VERIFIED_SAMPLES points (of its own num_samples, where fewer)."""
  if model is None:
    return None
  return dataclasses.replace(model, draws=VERIFIED_DRAWS,
                             num_samples=min(model.num_samples, VERIFIED_SAMPLES))


# Coarse to fine (farthest-point keypoints with verification, the register defaults): the
# pose is first sought from the first COARSE_KEYPOINTS farthest-point keypoints of each
# cloud (the same even spread, half as dense), and a verified pose that is confident and
# clearly the best (`verification.clearly_confident`) is taken there; any other pair is
# registered from all the keypoints, exactly as without this step (`coarse_to_fine`).
# Half the keypoints is half the network's work and a quarter of the matching's
# (docs/registration.md).
COARSE_KEYPOINTS = 512


@dataclasses.dataclass
class CloudFeatures:
  """Keypoints of one cloud and their descriptors."""
  xyz: np.ndarray          # [K, 3] metres
  descriptors: np.ndarray  # [K, D]
  seconds: dict
  note: str = ''           # the keypoint fallback used, if any (one line)
  grid: str = ''           # what `to_grid` did (one line), if it ran


class FeatureLevels:
  """One cloud's keypoints, made and described as they are needed, coarse to fine.

  points [N, 3] metres (the search surface, near the origin); levels: per level, its
  sorted keypoint indices into points, or a callable that makes them on first use
  (timed as 'keypoints'); describe(idx [k]) -> descriptors [k, D] at points[idx];
  offset [3] added to the keypoints' coordinates (the cloud's frame, `local_origin`).
  `levels` lists the callables `coarse_to_fine` takes, coarse first. Each point's
  descriptor is computed once, and `seconds['descriptors']` sums the time spent on
  them. A keypoint's descriptor does not depend on the others described with it
  (learned; FPFH but on a cloud it describes over its search grid,
  `features.searched_on_grid`, which the 0.2 m grid of the register command's defaults
  never is), so each level's descriptors are those of its keypoints described at once.
  """

  def __init__(self, points: np.ndarray, levels: Sequence,
               describe: Callable[[np.ndarray], np.ndarray],
               offset: np.ndarray | None = None, note: str = '', grid: str = '',
               seconds: dict | None = None):
    self._points, self._levels, self._describe = points, list(levels), describe
    self._offset = np.zeros(3) if offset is None else np.asarray(offset, np.float64)
    self.note, self.grid = note, grid
    self.seconds = {'keypoints': 0.0, 'descriptors': 0.0, **(seconds or {})}
    # The points described so far (sorted indices [k]) and their descriptors [k, D].
    self._known = np.zeros(0, np.int64)
    self._descriptors: np.ndarray | None = None

  def keypoints(self, level: int = -1) -> np.ndarray:
    """Sorted keypoint indices [K] of a level (default the finest)."""
    if callable(self._levels[level]):
      t0 = time.perf_counter()
      self._levels[level] = np.asarray(self._levels[level](), np.int64)
      self.seconds['keypoints'] += time.perf_counter() - t0
    return self._levels[level]

  @property
  def idx(self) -> np.ndarray:
    """The finest level's keypoint indices."""
    return self.keypoints(-1)

  def level(self, n: int) -> CloudFeatures:
    """Level n's keypoints [K, 3] (in the cloud's frame) and their descriptors."""
    idx = self.keypoints(n)
    need = np.setdiff1d(idx, self._known)
    if len(need):
      t0 = time.perf_counter()
      d = self._describe(need)
      known = np.concatenate([self._known, need])
      order = np.argsort(known, kind='stable')
      self._known = known[order]
      self._descriptors = (d if self._descriptors is None
                           else np.concatenate([self._descriptors, d]))[order]
      self.seconds['descriptors'] += time.perf_counter() - t0
    xyz = np.asarray(self._points)[idx].astype(np.float64) + self._offset
    rows = np.searchsorted(self._known, idx)
    return CloudFeatures(xyz, self._descriptors[rows], self.seconds, self.note, self.grid)

  @property
  def levels(self) -> list[Callable[[], CloudFeatures]]:
    return [functools.partial(self.level, n) for n in range(len(self._levels))]

  def described(self) -> np.ndarray:
    """[k, D] the descriptors computed so far, in point order."""
    return np.zeros((0, 0), np.float32) if self._descriptors is None else self._descriptors


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


def voxel_size_of(model=None) -> float:
  """Metres: the grid `model`'s features expect (`VOXEL_SIZE` for FPFH or no model)."""
  return float(getattr(model, 'voxel_size', VOXEL_SIZE)) if model is not None else VOXEL_SIZE


def to_grid(points: np.ndarray, voxel: float) -> tuple[np.ndarray, str]:
  """points [N, 3] metres on the `voxel` m grid the features were made for: the centroid
  of each occupied cell (Open3D), in the input's coordinates and float type, so a dense
  scan or a map tile costs what a 0.2 m-voxel scan does. -> (cloud [M, 3], one line
  saying what was done: '' for voxel <= 0, which keeps every point)."""
  if voxel <= 0:
    return points, ''
  # Counted first (numpy): a cloud already on such a grid needs no Open3D at all.
  if preprocess.occupied_voxels(points, voxel) >= ON_GRID * len(points):
    return points, (f'{len(points):,} points, no denser than the {voxel:g} m grid: used as '
                    'given')
  down = preprocess.voxel_downsample(points, voxel, points.dtype)
  return down, f'{len(points):,} -> {len(down):,} points on the {voxel:g} m grid'


def compute_keypoints(points: np.ndarray, method: str, model=None, seed: int = 0,
                      num_random: int = keypoints_lib.FARTHEST_POINT_KEYPOINTS,
                      fallback: bool = True) -> tuple[np.ndarray, str]:
  """Keypoint indices into points [N, 3] and a note ('' or the fallback used):

    auto     `num_random` farthest-point keypoints: evenly spread, so found again in a
             scan from another sensor or standpoint (docs/notes/cross_sensor.md), the way the
             network's training samples its cluster centres; the register default (of
             the model's `keypoint_domain`, `domain_of`)
    iss      ISS with the paper's radii (docs/method.md §4); with `fallback`, a sparse
             cloud falls back to wider radii, then farthest-point keypoints
             (`keypoints.iss_with_fallbacks`); without, the evaluation protocol
    learned  attention + NMS (needs a detector-trained `inference.Model`)
    random   `num_random` random points
  """
  points = check_cloud(points)
  if method == 'auto':
    keypoints_lib.check_registrable(points, 'auto keypoints')
    among = keypoint_domain(points, domain_of(model))
    return among[keypoints_lib.farthest_point_keypoints(points[among], num_random)], ''
  if method == 'iss':
    if fallback:
      return keypoints_lib.iss_with_fallbacks(points)
    return keypoints_lib.iss(points), ''
  if method == 'random':
    return keypoints_lib.random_keypoints(np.random.default_rng(seed), len(points), num_random), ''
  if method == 'learned':
    if model is None:
      raise ValueError('learned keypoints need a model (--checkpoint)')
    return inference.detect(model, points)[0], ''
  raise ValueError(f'keypoints must be one of {KEYPOINTS}, got {method!r}')


def compute_descriptors(points: np.ndarray, keypoint_idx: np.ndarray, method: str,
                        model=None, search: str = 'kdtree',
                        fpfh_max_nn: int = features.FPFH_MAX_NN) -> np.ndarray:
  """[K, D] descriptors at points[keypoint_idx]: FPFH (docs/method.md §4) or learned."""
  points = check_cloud(points)
  keypoint_idx = np.asarray(keypoint_idx)
  if keypoint_idx.ndim != 1 or (keypoint_idx.size and not (
      np.issubdtype(keypoint_idx.dtype, np.integer) and 0 <= keypoint_idx.min()
      and keypoint_idx.max() < len(points))):
    raise ValueError(f'keypoint_idx must be [K] integer indices into the {len(points)} '
                     f'points, got shape {keypoint_idx.shape} dtype {keypoint_idx.dtype}')
  if method == 'fpfh':
    return features.fpfh(points, keypoint_idx, max_nn=fpfh_max_nn)
  if method == 'learned':
    if model is None:
      raise ValueError('learned descriptors need a model (--checkpoint)')
    return inference.describe(model, points, points[keypoint_idx], search=search)
  raise ValueError(f'descriptor must be one of {DESCRIPTORS}, got {method!r}')


def cloud_features(points: np.ndarray, keypoints: str = 'iss', descriptor: str = 'fpfh',
                   model=None, seed: int = 0, fpfh_max_nn: int = features.FPFH_MAX_NN,
                   voxel: float | None = None, progress=None) -> CloudFeatures:
  """Keypoints of points [N, 3] (finite metres, within float32's centimetre range of the
  origin) and their descriptors, computed on the cloud put on the `voxel` m grid
  (`to_grid`; None: `voxel_size_of(model)`, 0: every point as given). Keypoints are
  points of that grid, in the input's coordinates. `progress(stage)`, if given, is
  called as each stage starts. Raises ValueError on a malformed cloud or when the
  detector finds fewer than 3 keypoints."""
  points = check_cloud(points)
  t0 = time.perf_counter()
  points, grid = to_grid(points, voxel_size_of(model) if voxel is None else voxel)
  t1 = time.perf_counter()
  if progress is not None:
    progress('keypoints')
  idx, note = compute_keypoints(points, keypoints, model, seed)
  if len(idx) < 3:
    raise ValueError(f'{keypoints} keypoints: found {len(idx)} in a cloud of {len(points)} '
                     'points, 3 are needed (too sparse, or planar / collinear?)')
  t2 = time.perf_counter()
  if progress is not None:
    progress('descriptors')
  desc = compute_descriptors(points, idx, descriptor, model, fpfh_max_nn=fpfh_max_nn)
  t3 = time.perf_counter()
  return CloudFeatures(points[idx], desc,
                       {'grid': t1 - t0, 'keypoints': t2 - t1, 'descriptors': t3 - t2}, note, grid)


def domain_of(model) -> str:
  """What 'auto' keypoints are sampled from with `model` (`inference.KEYPOINT_SELECTIONS`):
  its config's `inference.keypoints`; 'all' without a model."""
  return getattr(model, 'keypoints', 'all') if model is not None else 'all'


def keypoint_domain(points: np.ndarray, domain: str = 'all') -> np.ndarray:
  """Sorted indices into points [N, 3] (metres, z up) that 'auto' keypoints are sampled
  from: every point ('all'), or the points above the ground ('structure':
  `bev.height_above_ground` over `bev.HEIGHT`'s floor: walls, poles, trunks, cars,
  canopies), all of them where fewer than `keypoints.ENOUGH_KEYPOINTS` rise. Two scans of
  one unit draw the same rings on the ground at the same ranges from their sensors; for a
  unit whose matches there pull two standpoints together, `experiments.adapt` picks
  'structure' (`keypoint_choice`, docs/notes/cross_sensor.md)."""
  if domain not in inference.KEYPOINT_SELECTIONS:
    raise ValueError(f'keypoint domain must be one of {inference.KEYPOINT_SELECTIONS}, '
                     f'got {domain!r}')
  if domain == 'all':
    return np.arange(len(points))
  rising = np.flatnonzero(bev.height_above_ground(points) > bev.HEIGHT[0])
  return rising if len(rising) >= keypoints_lib.ENOUGH_KEYPOINTS else np.arange(len(points))


def auto_keypoints(points: np.ndarray, num: int = keypoints_lib.FARTHEST_POINT_KEYPOINTS,
                   coarse: int = COARSE_KEYPOINTS, domain: str = 'all'
                   ) -> tuple[np.ndarray, np.ndarray]:
  """`compute_keypoints(points, 'auto')` (of the `keypoint_domain`) and its coarse level:
  (sorted indices [K] into points [N, 3], positions in them of the first `coarse`
  farthest-point picks)."""
  points = check_cloud(points)
  keypoints_lib.check_registrable(points, 'auto keypoints')
  among = keypoint_domain(points, domain)
  order = among[keypoints_lib.farthest_point_order(points[among], num)]
  idx = np.unique(order)
  return idx, np.searchsorted(idx, np.unique(order[:coarse]))


def coarse_keypoints(verified: bool) -> int:
  """The coarse level's keypoint count: COARSE_KEYPOINTS where the poses are verified (a
  level ends the search only on a verified pose), else 0 (one level)."""
  return COARSE_KEYPOINTS if verified else 0


def feature_levels(points: np.ndarray, keypoints: str = 'auto', descriptor: str = 'learned',
                   model=None, seed: int = 0, fpfh_max_nn: int = features.FPFH_MAX_NN,
                   coarse: int = COARSE_KEYPOINTS) -> FeatureLevels:
  """The `FeatureLevels` of one cloud [N, 3] (on its grid already, any coordinates: as
  `features_anywhere`): with 'auto' keypoints and `coarse` > 0 two levels, the first
  `coarse` farthest-point picks (of `keypoint_domain`), then all
  `keypoints.FARTHEST_POINT_KEYPOINTS` (the sampling continued only where a pair needs
  them), else one. Nothing is described yet."""
  points = check_cloud(points, dtype=np.float64)
  offset = local_origin(points)
  local = check_cloud(points - offset)
  t0 = time.perf_counter()
  note = ''
  if keypoints == 'auto' and coarse > 0:
    keypoints_lib.check_registrable(local, 'auto keypoints')
    among = keypoint_domain(local, domain_of(model))
    sampler = keypoints_lib.FarthestPointSampler(local[among])
    levels = [lambda: among[np.unique(sampler.order(coarse))],
              lambda: among[np.unique(sampler.order(keypoints_lib.FARTHEST_POINT_KEYPOINTS))]]
  else:
    idx, note = compute_keypoints(local, keypoints, model, seed)
    if len(idx) < 3:
      raise ValueError(f'{keypoints} keypoints: found {len(idx)} in a cloud of {len(local)} '
                       'points, 3 are needed (too sparse, or planar / collinear?)')
    levels = [idx]
  describe = lambda at: compute_descriptors(local, at, descriptor, model,
                                            fpfh_max_nn=fpfh_max_nn)
  return FeatureLevels(local, levels, describe, offset, note,
                       seconds={'keypoints': time.perf_counter() - t0})


def _match_stats(xyz1: np.ndarray, xyz2: np.ndarray, transform: np.ndarray,
                 inlier_threshold: float) -> tuple[np.ndarray, dict]:
  """Over matches xyz1[i] <-> xyz2[i] under T_12: (which are within the threshold [C],
  Open3D's RegistrationResult numbers)."""
  residual = np.linalg.norm(xyz2 @ transform[:3, :3].T + transform[:3, 3] - xyz1, axis=1)
  close = residual < inlier_threshold
  rmse = float(np.sqrt(np.mean(residual[close] ** 2))) if close.any() else 0.0
  return close, {'fitness': float(close.mean()), 'inlier_rmse': rmse,
                 'correspondence_set_size': int(close.sum())}


def estimate(f1: CloudFeatures, f2: CloudFeatures, seed: int = 0, inlier_threshold: float = 1.0,
             confidence: float = 0.99, max_trials: int = 10_000,
             estimator: str = 'rigid', candidates: int = 1,
             sampling: str = 'auto') -> Registration:
  """Descriptor matches, then RANSAC with the motion model `estimator` (`ESTIMATORS`):
  the rigid one over the nearest neighbours of cloud 1's keypoints among cloud 2's, the
  upright one as `sampling` says (`SAMPLINGS`). With `candidates` > 1 (upright only) the
  result keeps that many distinct best poses for `verify`."""
  if estimator not in ESTIMATORS:
    raise ValueError(f'estimator must be one of {ESTIMATORS}, got {estimator!r}')
  if sampling not in SAMPLINGS:
    raise ValueError(f'sampling must be one of {SAMPLINGS}, got {sampling!r}')
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


def verify(reg: Registration, f1: CloudFeatures, f2: CloudFeatures, points1, points2=None,
           inlier_threshold: float = 1.0, bev_candidates: int = 0,
           confident_only: bool = False) -> Registration:
  """`reg` with the candidate pose (`estimate(candidates=k)`) that, refined by ICP, lays the
  most of cloud 2's structure on cloud 1 (`verification.verify`). points1, points2: the
  clouds [N, 3] (metres near the origin, in the features' coordinates) or their
  `prepared.PreparedCloud`s, which keep what is made of a cloud for its next pair; or
  points1 a `prepared.PreparedPair` (points2 None), which also keeps the BEV search's
  poses and every ICP for the pair's next registration. With `bev_candidates` b > 0
  (upright scans), unless RANSAC's best already lays `verification.CONFIDENT_FITNESS` of
  cloud 2's structure on cloud 1, the b best poses of the bird's-eye-view search
  (`bev.search`) are checked too, after RANSAC's, all together. Inliers and the
  RegistrationResult numbers are recounted over the matches under the chosen pose;
  `verified_fitness` has one entry per candidate checked (k, or k + b); `seconds` gains
  'bev' (0 where it was not needed) and 'verify'. `confident_only`: only a pose fitting
  CONFIDENT_FITNESS is of use (no BEV search then): candidates far from it are not
  refined in full (`verification.verify`); so it is for RANSAC's candidates alone before
  the BEV search's join them."""
  t0 = time.perf_counter()
  pair = prepared.prepare_pair(points1, points2)
  target, source = pair.cloud1.target, pair.cloud2.source
  candidates = reg.candidates if reg.candidates is not None else reg.transform[None]
  # With the BEV search to follow, RANSAC's candidates alone only decide whether it runs
  # (a confident pose), and the call with both refines what wins: none is refined in full
  # here unless it could be confident (`confident_only`).
  best, refined, fitness = verification.verify(target, source, candidates, memo=pair.memo,
                                               confident_only=confident_only or bev_candidates > 0)
  seconds = {**reg.seconds, 'verify': time.perf_counter() - t0}
  if bev_candidates > 0:
    seconds['bev'] = 0.0
    if fitness[best] < verification.CONFIDENT_FITNESS:
      t1 = time.perf_counter()
      candidates = np.concatenate([candidates, pair.bev_poses(bev_candidates)])
      t2 = time.perf_counter()
      best, refined, fitness = verification.verify(target, source, candidates,
                                                   memo=pair.memo)
      seconds['bev'] = t2 - t1
      seconds['verify'] += time.perf_counter() - t2
  # Among them, the one that also leaves each scan's empty space empty (`free_space.best`).
  best = free_space.best(fitness, lambda c: pair.conflict(refined[c]))
  xyz1 = f1.xyz[reg.matches[:, 0]].astype(np.float64)
  xyz2 = f2.xyz[reg.matches[:, 1]].astype(np.float64)
  inliers, stats = _match_stats(xyz1, xyz2, refined[best], inlier_threshold)
  return dataclasses.replace(reg, transform=refined[best], inliers=inliers, seconds=seconds,
                             verified_fitness=fitness, verified_poses=refined, **stats)


def coarse_to_fine(levels1: Sequence[Callable[[], CloudFeatures]],
                   levels2: Sequence[Callable[[], CloudFeatures]], points1, points2=None, *,
                   seed: int = 0, inlier_threshold: float = 1.0, confidence: float = 0.99,
                   max_trials: int = 10_000, estimator: str = 'upright', candidates: int = 10,
                   bev_candidates: int = 0, verified: bool = True, progress=None,
                   sampling: str = 'auto'
                   ) -> tuple[Registration, CloudFeatures, CloudFeatures]:
  """`estimate` (`candidates` poses) and, where `verified`, `verify` on each level of the
  two clouds' features in turn (callables, coarse first: `FeatureLevels.levels`), until a
  level's verified pose lays `verification.CONFIDENT_FITNESS` of cloud 2's structure on
  cloud 1 and no distinct candidate comes near it (`verification.clearly_confident`).
  The last level is the registration without levels, the BEV search's candidates
  included; the ones before only end it early (unverified, only the last level runs).
  points1, points2: as for `verify`; `progress(stage)` as for `register`, on the first
  level tried; `sampling` as for `estimate`. -> (registration, features of cloud 1, of
  cloud 2) of the level that decided, its `seconds` summed over the levels tried and
  `levels_tried` set."""
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
                   confident_only=not last)
    for name, s in reg.seconds.items():
      spent[name] = spent.get(name, 0.0) + s
    if last or verification.clearly_confident(reg.verified_poses, reg.verified_fitness):
      return dataclasses.replace(reg, seconds=spent, levels_tried=n - first + 1), f1, f2


def assess(reg: Registration, points1, points2=None, origin: np.ndarray | None = None
           ) -> Registration:
  """`reg` with its `uncertainty` at its transform (`uncertainty.assess`) and its
  `verdict` (`verdict.assess`): points1, points2 as for `verify`; `origin` [3]: cloud 1's
  frame origin in their coordinates (default 0; free space is judged only where it is 0,
  the clouds in their sensors' frames). Uses the verification's candidates where `reg`
  was verified."""
  t0 = time.perf_counter()
  pair = prepared.prepare_pair(points1, points2)
  cloud1, cloud2 = pair.cloud1, pair.cloud2
  assessed = uncertainty_lib.assess(cloud1.target, cloud2.source.points, reg.transform,
                                    reg.verified_poses, reg.verified_fitness, origin)
  judged = verdict_lib.assess(pair, reg.transform, assessed.free, reg.verified_poses,
                              reg.verified_fitness,
                              judge_free_space=origin is None or not np.any(origin))
  return dataclasses.replace(reg, uncertainty=assessed, verdict=judged,
                             seconds={**reg.seconds, 'assess': time.perf_counter() - t0})


def local_origin(*clouds: np.ndarray) -> np.ndarray:
  """[3] float64: zero when float32 resolves every point of `clouds` ([N, 3] float64
  metres) to clean.MAX_RESOLUTION, else the first cloud's centroid, the origin to
  compute features around."""
  reach = max(float(np.max(np.abs(c))) for c in clouds)
  if np.spacing(np.float32(reach)) <= clean.MAX_RESOLUTION:
    return np.zeros(3)
  return clouds[0].mean(axis=0)


def features_anywhere(points: np.ndarray, keypoints: str = 'iss', descriptor: str = 'fpfh',
                      model=None, seed: int = 0, fpfh_max_nn: int = features.FPFH_MAX_NN,
                      voxel: float | None = None, progress=None) -> CloudFeatures:
  """`cloud_features` of one cloud [N, 3] in any coordinates (float64 metres, e.g. UTM):
  computed around `local_origin(points)`, keypoints returned in the input coordinates
  as float64. Features of each cloud once, for registering many pairs (`estimate`
  then works in the input coordinates, in float64)."""
  points = check_cloud(points, dtype=np.float64)
  offset = local_origin(points)
  f = cloud_features(check_cloud(points - offset), keypoints, descriptor, model, seed,
                     fpfh_max_nn, voxel, progress)
  f.xyz = f.xyz.astype(np.float64) + offset
  return f


@dataclasses.dataclass(frozen=True)
class Options:
  """How `register` and `register_many` register a pair. The defaults are the register
  command's (docs/registration.md); `Options.paper()` is the paper's protocol.

  keypoints   KEYPOINTS: 'auto' (1,024 farthest-point keypoints, the first 512 tried
              alone where the poses are verified: `coarse_to_fine`), 'iss' (the paper's;
              a pair RANSAC cannot sample is registered again with farthest-point
              keypoints), 'learned' (a detector model), 'random'.
  descriptor  DESCRIPTORS: 'learned' (needs a model) or 'fpfh'.
  estimator   ESTIMATORS: 'upright' (2-point samples of a turn about z and a shift, for
              scans whose z axis is up) or 'rigid' (3-point samples, any rotation).
  sampling    SAMPLINGS, the upright estimator's matches and samples: 'compatible'
              (matches both ways, samples among the pairs of matches that one turn
              about z and shift can fit), 'uniform' (cloud 1's nearest neighbours,
              uniform draws) or 'auto' (compatible with verify = 0, else uniform).
  verify      RANSAC's this many distinct best poses checked against the clouds by ICP
              (`verification`); 0 keeps RANSAC's best as it is.
  bev         the bird's-eye-view search's this many best poses checked with them, where
              they apply: upright estimator and verify > 0 (`bev_candidates`).
  icp         point-to-plane ICP from the chosen pose (1 m, then 0.5 m).
  draws       samplings of each ball the learned descriptor averages: None,
              VERIFIED_DRAWS of VERIFIED_SAMPLES points where verify > 0, else the
              model's own; 0 the model's own (`describing`).
  voxel       metres of the grid each cloud is put on first (`to_grid`); None the
              model's (0.2 m), 0 every point as given.
  fpfh_max_nn FPFH's neighbour cap within its 4 m ball (0: none, the paper's).
  seed        RANSAC's (and random keypoints') seed.
  level       LEVELS: 'ground' (each scan whose ground is tilted by LEVEL_MIN_TILT_DEG or
              more is first turned level about its sensor, `leveling`, and every pose
              comes back in the scans' own frames; a pair with a scan of no ground keeps
              its pose as given where verified clear, else is registered with FPFH and
              RANSAC over any rotation, and notes say which) or
              'none' (the clouds as given: z is taken to be up). `register_many` levels
              each cloud once.
  """
  keypoints: str = 'auto'
  descriptor: str = 'learned'
  estimator: str = 'upright'
  verify: int = 10
  bev: int = 5
  icp: bool = False
  draws: int | None = None
  voxel: float | None = None
  fpfh_max_nn: int = features.FPFH_MAX_NN
  seed: int = 0
  level: str = 'ground'
  sampling: str = 'auto'

  def __post_init__(self):
    for name, allowed in (('keypoints', KEYPOINTS), ('descriptor', DESCRIPTORS),
                          ('estimator', ESTIMATORS), ('level', LEVELS),
                          ('sampling', SAMPLINGS)):
      if getattr(self, name) not in allowed:
        raise errors.UserError(f'{name} must be one of {allowed}, got {getattr(self, name)!r}')
    for name, meaning in (('verify', '0: no verification'), ('bev', '0: no BEV search'),
                          ('fpfh_max_nn', '0: no cap'), ('draws', "0: the model's own"),
                          ('voxel', '0: every point as given')):
      value = getattr(self, name)
      if value is not None and value < 0:
        raise errors.UserError(f'{name} must be >= 0 ({meaning}), got {value}')

  @classmethod
  def paper(cls, descriptor: str = 'fpfh', **overrides) -> 'Options':
    """The paper's protocol: ISS keypoints, RANSAC over any rotation, no verification,
    the clouds as given."""
    return cls(**{'keypoints': 'iss', 'descriptor': descriptor, 'estimator': 'rigid',
                  'verify': 0, 'bev': 0, 'level': 'none', 'sampling': 'uniform',
                  **overrides})

  @property
  def bev_candidates(self) -> int:
    """The BEV search's poses checked: `bev` with the upright estimator and verify > 0
    (its poses turn about z only and are checked with RANSAC's), else 0."""
    return self.bev if self.estimator == 'upright' and self.verify > 0 else 0

  @property
  def needs_model(self) -> bool:
    return self.descriptor == 'learned' or self.keypoints == 'learned'

  def describing(self, model):
    """`model` (an `inference.Model`) as these options describe with it (`draws`); None
    where no model is needed; a UserError where one is needed and not given."""
    if not self.needs_model:
      return None
    if model is None:
      raise errors.UserError(f'{self.keypoints} keypoints + {self.descriptor} descriptors '
                             "need a model (e.g. pretrained.load('ours'))")
    if self.draws is None:
      return verified_model(model) if self.verify > 0 else model
    return dataclasses.replace(model, draws=self.draws) if self.draws else model


def _register_levels(levels, fallback, cloud1, cloud2, options: Options, progress=None):
  """`coarse_to_fine` on two clouds' `FeatureLevels`; where ISS keypoints leave RANSAC
  nothing to sample (too few, or every sample degenerate: a ValueError), again on
  `fallback()`'s farthest-point levels. -> (registration, features of cloud 1, of cloud
  2, the levels used, a note on the fallback or '')."""
  def run(levels1, levels2):
    return coarse_to_fine(levels1.levels, levels2.levels, cloud1, cloud2, seed=options.seed,
                          estimator=options.estimator, candidates=max(options.verify, 1),
                          bev_candidates=options.bev_candidates, verified=options.verify > 0,
                          progress=progress, sampling=options.sampling)
  try:
    return (*run(*levels), levels, '')
  except ValueError as e:
    if options.keypoints != 'iss':
      raise
    levels = fallback()
    return (*run(*levels), levels, f'{e}; registered again with {len(levels[0].idx)} / '
            f'{len(levels[1].idx)} farthest-point keypoints')


def _finish(reg: Registration, cloud1, cloud2, options: Options, origin=None,
            progress=None) -> Registration:
  """ICP where the options ask for it, then the pose's assessment (`assess`)."""
  if options.icp:
    if progress is not None:
      progress('ICP')
    t0 = time.perf_counter()
    reg.transform, reg.icp_fitness = refine_icp(cloud1.points, cloud2.points, reg.transform)
    reg.seconds['icp'] = time.perf_counter() - t0
  return assess(reg, cloud1, cloud2, origin=origin)


# Degrees: with `Options.level`, a scan whose ground is tilted by less than this is used as
# it is (upright RANSAC's refit in 6 degrees of freedom and the ICP absorb it): the real
# KITTI scans beside the project sit 2.3 degrees off their ground.
LEVEL_MIN_TILT_DEG = 3.0


def _leveling(clouds, offset, options: Options, names):
  """Each cloud's `leveling.Leveling` (in its centred coordinates) where `options.level`
  asks for it, and the one-line notes of what was done."""
  if options.level == 'none':
    return [leveling.unchanged() for _ in clouds], []
  level = [leveling.level(c - offset, min_tilt_deg=LEVEL_MIN_TILT_DEG,
                          sensor_at_origin=not offset.any()) for c in clouds]
  notes = []
  for name, lv in zip(names, level):
    if lv.sparse:
      notes.append(f'{name}: too few points to find its ground '
                   f'(< {leveling.MIN_POINTS_TO_LEVEL:,}); used as it is')
    elif lv.note:
      notes.append(f'{name}: {lv.note}')
    elif lv.turned:
      notes.append(f'{name}: levelled, its ground {lv.tilt_deg:.1f} degrees off horizontal')
  return level, notes


# A pair with a scan of no ground (`Leveling.note`) is registered as given first, where its
# poses are verified: most such scans are upright (a sparse re-scan whose ground holds too
# few points, an indoor scan of walls), and a pose verified as `_settled` is as sure as any
# other pair's. Otherwise nothing may assume z is up: FPFH and RANSAC over any rotation.
UPRIGHT_NOTE = 'registered as given (z up): its verified pose is clear'
ANY_ROTATION_NOTE = 'registered with FPFH and RANSAC over any rotation'


def _settled(reg: Registration) -> bool:
  """Whether a verified registration's best pose is clear (`clearly_confident`)."""
  return reg.verified_fitness is not None and verification.clearly_confident(
      reg.verified_poses, reg.verified_fitness)


def _any_rotation(options: Options) -> Options:
  """The options of the rotation-invariant path (clouds levelled, or left, already)."""
  return dataclasses.replace(options, descriptor='fpfh', estimator='rigid', level='none')


def _unlevel(reg: Registration, level) -> Registration:
  """A registration of levelled clouds in their own frames: every pose T' -> L1^-1 T' L2."""
  back = lambda t: np.linalg.inv(level[0].matrix) @ t @ level[1].matrix
  many = lambda ts: None if ts is None else np.stack([back(t) for t in ts])
  return dataclasses.replace(reg, transform=back(reg.transform),
                             candidates=many(reg.candidates),
                             verified_poses=many(reg.verified_poses))


def register(*, target: np.ndarray, source: np.ndarray, model=None,
             options: Options | None = None, progress=None
             ) -> tuple[Registration, CloudFeatures, CloudFeatures]:
  """Register `source` onto `target`: the transform T_12 maps source points into the
  target's frame (target = cloud 1, source = cloud 2 in every table and file).

  target [N1, 3] and source [N2, 3] metres, any float type and coordinates; model: an
  `inference.Model` where `options` need one (default `Options()`, the register
  command's). Clouds that float32 cannot resolve to MAX_RESOLUTION (e.g. UTM
  coordinates) are shifted by one common offset, the target's centroid in float64,
  before any float32 step; T_12 and the keypoints come back in the input coordinates.
  Each cloud is put on the options' grid first (`to_grid`; each feature's `grid` says
  what was done). `progress(stage)`, if given, is called as each stage starts.
  -> (registration, features of the target, features of the source).
  """
  options = Options() if options is None else options
  model = options.describing(model)
  clouds = [check_cloud(p, name, np.float64) for p, name in ((target, 'cloud 1'),
                                                             (source, 'cloud 2'))]
  offset = local_origin(clouds[0], clouds[1])
  voxel = voxel_size_of(model) if options.voxel is None else options.voxel
  stage = (lambda name: None) if progress is None else progress
  names = ('cloud 1', 'cloud 2')
  level, notes = _leveling(clouds, offset, options, names)
  groundless = any(lv.note for lv in level)

  def any_rotation():
    reg, f1, f2 = register(target=target, source=source, model=model,
                           options=_any_rotation(options), progress=progress)
    reg.notes = notes + [ANY_ROTATION_NOTE] + reg.notes
    return reg, f1, f2

  if groundless and not options.verify:
    return any_rotation()
  local, grids = [], []
  for c, lv, name in zip(clouds, level, names):
    stage(f'{name}: grid')
    t0 = time.perf_counter()
    cloud, grid = to_grid(check_cloud(lv.apply(c - offset), name), voxel)
    local.append(cloud)
    grids.append((grid, time.perf_counter() - t0))
  coarse = coarse_keypoints(options.verify > 0)

  def levels_of(n, kind):
    stage(f'{names[n]}: keypoints')
    levels = feature_levels(local[n], kind, options.descriptor, model, options.seed,
                            options.fpfh_max_nn, coarse)
    levels.keypoints(0)
    stage(f'{names[n]}: descriptors')
    levels.levels[0]()   # the first level's, timed as this stage
    levels.grid, levels.seconds['grid'] = grids[n]
    return levels

  levels = [levels_of(n, options.keypoints) for n in range(2)]
  notes += [f'{name}: {f.note}' for name, f in zip(names, levels) if f.note]
  cloud1, cloud2 = (prepared.PreparedCloud(c) for c in local)
  reg, f1, f2, _, fallback = _register_levels(
      levels, lambda: [levels_of(n, 'auto') for n in range(2)], cloud1, cloud2, options, stage)
  if groundless:
    if not _settled(reg):
      return any_rotation()
    notes.append(UPRIGHT_NOTE)
  reg.notes = notes + ([fallback] if fallback else [])
  if any(lv.turned for lv in level):
    # Back in the clouds' own (centred) frames: T = L1^-1 T' L2, the clouds turned back.
    reg = _unlevel(reg, level)
    cloud1, cloud2 = (prepared.PreparedCloud(lv.undo(c)) for lv, c in zip(level, local))
    f1.xyz, f2.xyz = level[0].undo(f1.xyz), level[1].undo(f2.xyz)
  reg = _finish(reg, cloud1, cloud2, options, origin=-offset, progress=stage)
  # T in centred coordinates maps p - o to q - o; in the caller's: q = R p + t + o - R o.
  to_local = np.eye(4)
  to_local[:3, 3] = -offset
  reg.transform = np.linalg.inv(to_local) @ reg.transform @ to_local
  f1.xyz, f2.xyz = (f.xyz.astype(np.float64) + offset for f in (f1, f2))
  return reg, f1, f2


# Clouds `register_many` keeps: a KITTI-size scan costs ~5 MB (points, normals, KD-tree,
# footprint, descriptors).
CACHE_SIZE = 64
# What `register_many` times per pair, in order: the first five only for a cloud met first.
STAGES = ('read', 'grid', 'level', 'keypoints', 'descriptors', 'matching', 'ransac', 'bev',
          'verify', 'icp', 'assess')


@dataclasses.dataclass
class PairResult:
  """One pair of `register_many`: T_12 maps the source into the target's frame."""
  target: str                               # path of cloud 1
  source: str                               # path of cloud 2
  registration: Registration | None = None  # None where the pair failed
  target_features: CloudFeatures | None = None
  source_features: CloudFeatures | None = None
  error: str = ''                           # why the pair failed, one line ('' if not)
  seconds: float = 0.0                      # wall time of this pair


@dataclasses.dataclass
class _Cloud:
  points: prepared.PreparedCloud   # on the grid, float64, levelled (`Options.level`)
  features: FeatureLevels          # keypoints and descriptors of `points`
  seconds: dict                    # read / grid / level, once
  level: leveling.Leveling         # how `points` was levelled
  own: prepared.PreparedCloud      # on the grid in the file's coordinates (ICP, assessment)


class Registrar:
  """Registers pairs of cloud files with one setting (`Options`), keeping the last
  `cache_size` clouds it met: each read (`read(path)` -> [N, 3] float64 metres, the
  file's coordinates), put on the grid, levelled (`Options.level`), described (its coarse
  level first, the rest when a pair needs it) and prepared for the BEV search and the
  verification once. `say(line)` gets the one-line notes (grid, levelling, keypoint
  fallbacks). `register_many` streams pairs through one."""

  def __init__(self, read: Callable[[str], np.ndarray], *, model=None,
               options: Options | None = None, say: Callable[[str], None] = print,
               cache_size: int = CACHE_SIZE):
    self._options = Options() if options is None else options
    self._read, self._model, self._say = read, self._options.describing(model), say
    self._voxel = (voxel_size_of(self._model) if self._options.voxel is None
                   else self._options.voxel)
    self._kept: dict[str, _Cloud] = {}
    self._size = cache_size

  def levels(self, points: np.ndarray, keypoints: str) -> FeatureLevels:
    o = self._options
    return feature_levels(points, keypoints, o.descriptor, self._model, o.seed, o.fpfh_max_nn,
                          coarse_keypoints(o.verify > 0))

  def cloud(self, path: str) -> tuple[_Cloud, bool]:
    """The cloud at `path`, and whether it was made now (False: kept from before)."""
    if path in self._kept:
      self._kept[path] = self._kept.pop(path)   # the most recently used last
      return self._kept[path], False
    t0 = time.perf_counter()
    points = self._read(path)
    t1 = time.perf_counter()
    points, note = to_grid(points, self._voxel)
    t2 = time.perf_counter()
    if note:
      self._say(f'voxel: {os.path.basename(path)}: {note}')
    name = os.path.basename(path)
    offset = local_origin(points)
    own = prepared.PreparedCloud(points)
    (level,), notes = _leveling([points], offset, self._options, [name])
    level = dataclasses.replace(level, center=offset)   # found about the centred points
    for line in notes:
      self._say(line)
    points = level.apply(points)
    t3 = time.perf_counter()
    f = self.levels(points, self._options.keypoints)
    if f.note:
      self._say(f'{name}: {f.note}')
    self._kept[path] = _Cloud(prepared.PreparedCloud(points) if level.turned else own, f,
                              {'read': t1 - t0, 'grid': t2 - t1, 'level': t3 - t2}, level, own)
    if len(self._kept) > self._size:
      del self._kept[next(iter(self._kept))]
    return self._kept[path], True

  def register(self, path1: str, path2: str
               ) -> tuple[Registration, CloudFeatures, CloudFeatures]:
    """T_12 of the pair (maps cloud 2, the source, into cloud 1) -> (registration,
    features of cloud 1, of cloud 2); the registration's `seconds` holds every stage this
    pair cost (`STAGES`): reading and gridding a cloud met first, the keypoints and
    descriptors it made, matching, RANSAC, the BEV search, the verification, ICP and the
    assessment. A cloud that cannot be registered is a ValueError, a bad file the
    reader's error."""
    seconds = collections.defaultdict(float)
    entries = []
    for path in (path1, path2):
      entry, new = self.cloud(path)
      if new:
        for stage, s in entry.seconds.items():
          seconds[stage] += s
      entries.append(entry)
    groundless = any(e.level.note for e in entries)

    def any_rotation(tried: dict):
      # From the clouds kept on the grid; `tried`: the seconds of the upright try before.
      reg, f1, f2 = register(target=entries[0].own.points, source=entries[1].own.points,
                             model=self._model,
                             options=dataclasses.replace(_any_rotation(self._options),
                                                         voxel=0.0))
      spent = collections.Counter(seconds)
      spent.update(tried)
      spent.update(reg.seconds)
      for f in (f1, f2):
        spent.update({k: f.seconds[k] for k in ('keypoints', 'descriptors')})
      reg.seconds = dict(spent)
      reg.notes = [ANY_ROTATION_NOTE] + reg.notes
      return reg, f1, f2

    if groundless and not self._options.verify:
      return any_rotation({})
    levels = [e.features for e in entries]
    lazy = ('keypoints', 'descriptors')   # what the clouds' levels have cost until now
    before = {stage: sum(f.seconds[stage] for f in levels) for stage in lazy}
    reg, f1, f2, used, fallback = _register_levels(
        levels, lambda: [self.levels(e.points.points, 'auto') for e in entries],
        entries[0].points, entries[1].points, self._options)
    if fallback:
      self._say(f'{os.path.basename(path1)} / {os.path.basename(path2)}: {fallback}')
      levels = levels + list(used)
    for stage in lazy:
      seconds[stage] = sum(f.seconds[stage] for f in levels) - before[stage]
    if groundless:
      if not _settled(reg):
        return any_rotation(reg.seconds)
      reg.notes.append(UPRIGHT_NOTE)
    level = [e.level for e in entries]
    if any(lv.turned for lv in level):   # back in the files' frames; the kept features stay
      reg = _unlevel(reg, level)
      f1, f2 = (dataclasses.replace(f, xyz=lv.undo(f.xyz)) for f, lv in zip((f1, f2), level))
    reg = _finish(reg, entries[0].own, entries[1].own, self._options)
    reg.seconds = {**seconds, **reg.seconds}
    return reg, f1, f2


def register_many(pairs: Iterable[tuple[str, str]], read: Callable[[str], np.ndarray], *,
                  model=None, options: Options | None = None,
                  say: Callable[[str], None] = print, cache_size: int = CACHE_SIZE
                  ) -> Iterator[PairResult]:
  """Each (target path, source path) of `pairs` registered in turn, as a stream of
  `PairResult`s: consecutive scans of a drive, a scan against tens of loop-closure
  candidates, an evaluation set's pairs. Each cloud is made once among the last
  `cache_size` met (`Registrar`: `read`, `say` as there). A pair that fails on bad input
  (a missing or bad file, too few points, a flat cloud: a ValueError or OSError) gets its
  `error` and the others go on. Each registration's `seconds` holds what that pair cost,
  stage by stage (`STAGES`)."""
  clouds = Registrar(read, model=model, options=options, say=say, cache_size=cache_size)
  for path1, path2 in pairs:
    start = time.perf_counter()
    try:
      reg, f1, f2 = clouds.register(path1, path2)
    except (OSError, ValueError) as e:
      yield PairResult(path1, path2, error=str(e), seconds=time.perf_counter() - start)
    else:
      yield PairResult(path1, path2, reg, f1, f2, seconds=time.perf_counter() - start)


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
