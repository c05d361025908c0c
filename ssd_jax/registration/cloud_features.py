"""What is made of one cloud before any pair: the grid it is put on, its local origin, its
keypoints (by method, sampled from a domain: all points or the structure above the
ground), their descriptors, and the coarse-to-fine levels of both (`FeatureLevels`)."""

from __future__ import annotations

import dataclasses
import functools
import time
from typing import Callable, Sequence

import numpy as np

from ssd_jax import inference
from ssd_jax.data import clean, preprocess
from ssd_jax.data.clean import check_cloud
from ssd_jax.registration import bev, features, keypoints as keypoints_lib
from ssd_jax.registration import options as options_lib

# Metres: the voxel grid of every set the shipped models were trained and tested on
# (3DFeat-Net's processing), and so the grid every cloud is put on before its features
# (`to_grid`) unless the model says otherwise (`inference.Model.voxel_size`).
VOXEL_SIZE = 0.2
# A cloud that keeps at least this share of its points on the grid is on such a grid
# already, used as given: re-gridding would only move its points by a fraction of a cell.
# Clouds voxelised at 0.2 m on another grid keep 0.69-1.0 (every test set here), raw
# 64-beam scans ~0.3, anything twice as dense as the grid under 0.3.
ON_GRID = 0.6
# Metres: the verdict was calibrated on clouds whose points lie 0.1-0.3 m apart (median
# nearest neighbour); real drives thinned to 0.38 m keep its precision and recall, at 0.66 m
# 8 of 27 right poses were refused as free-space conflicts. A sparser cloud is told so.
SPARSE_SPACING = 0.5


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


class FeatureLevels:
  """One cloud's keypoints, made and described as they are needed, coarse to fine.

  points [N, 3] metres (the search surface, near the origin); levels: per level, its
  sorted keypoint indices into points, or a callable that makes them on first use
  (timed as 'keypoints'); describe(idx [k]) -> descriptors [k, D] at points[idx].
  `levels` lists the callables `coarse_to_fine` takes, coarse first. Each point's
  descriptor is computed once, and `seconds['descriptors']` sums the time spent on
  them. A keypoint's descriptor does not depend on the others described with it
  (learned; FPFH but on a cloud it describes over its search grid,
  `features.searched_on_grid`, which the 0.2 m grid of the register command's defaults
  never is), so each level's descriptors are those of its keypoints described at once.
  """

  def __init__(self, points: np.ndarray, levels: Sequence,
               describe: Callable[[np.ndarray], np.ndarray], note: str = '',
               seconds: dict | None = None):
    self._points, self._levels, self._describe = points, list(levels), describe
    self.note = note
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
    xyz = np.asarray(self._points)[idx].astype(np.float64)
    rows = np.searchsorted(self._known, idx)
    return CloudFeatures(xyz, self._descriptors[rows], self.seconds, self.note)

  @property
  def levels(self) -> list[Callable[[], CloudFeatures]]:
    return [functools.partial(self.level, n) for n in range(len(self._levels))]

  def described(self) -> np.ndarray:
    """[k, D] the descriptors computed so far, in point order."""
    return np.zeros((0, 0), np.float32) if self._descriptors is None else self._descriptors


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
    note = f'{len(points):,} points, no denser than the {voxel:g} m grid: used as given'
    spacing = keypoints_lib.point_spacing(points)
    if spacing > SPARSE_SPACING:
      note += (f'; its points lie {spacing:.2g} m apart (median): the verdict, calibrated '
               'on clouds 0.1-0.3 m apart, may refuse right poses')
    return points, note
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
    return auto_levels(points, domain_of(model), num=num_random)[-1](), ''
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
  raise ValueError(f'keypoints must be one of {options_lib.KEYPOINTS}, got {method!r}')


def compute_descriptors(points: np.ndarray, keypoint_idx: np.ndarray, method: str,
                        model=None, fpfh_max_nn: int = features.FPFH_MAX_NN) -> np.ndarray:
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
    return inference.describe(model, points, points[keypoint_idx])
  raise ValueError(f'descriptor must be one of {options_lib.DESCRIPTORS}, got {method!r}')


def cloud_features(points: np.ndarray, keypoints: str = 'iss', descriptor: str = 'fpfh',
                   model=None, seed: int = 0, fpfh_max_nn: int = features.FPFH_MAX_NN,
                   voxel: float | None = None) -> CloudFeatures:
  """Keypoints of points [N, 3] (finite metres, within float32's centimetre range of the
  origin) and their descriptors, computed on the cloud put on the `voxel` m grid
  (`to_grid`; None: `voxel_size_of(model)`, 0: every point as given): the one level of
  `feature_levels`. Keypoints are points of that grid, in the input's coordinates.
  Raises ValueError on a malformed cloud or when the detector finds fewer than 3."""
  points = check_cloud(points)
  t0 = time.perf_counter()
  points, _ = to_grid(points, voxel_size_of(model) if voxel is None else voxel)
  grid = time.perf_counter() - t0
  f = feature_levels(points, keypoints, descriptor, model, seed, fpfh_max_nn, 0).levels[-1]()
  return dataclasses.replace(f, seconds={'grid': grid, **f.seconds})


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
  'structure' (`keypoint_choice`, docs/notes/cross_sensor.md), and the register command
  tries it where a pose from every point is refused (`options.RETRIES`)."""
  if domain not in inference.KEYPOINT_SELECTIONS:
    raise ValueError(f'keypoint domain must be one of {inference.KEYPOINT_SELECTIONS}, '
                     f'got {domain!r}')
  if domain == 'all':
    return np.arange(len(points))
  rising = np.flatnonzero(bev.height_above_ground(points) > bev.HEIGHT[0])
  return rising if len(rising) >= keypoints_lib.ENOUGH_KEYPOINTS else np.arange(len(points))


def auto_levels(points: np.ndarray, domain: str = 'all', coarse: int = 0,
                num: int = keypoints_lib.FARTHEST_POINT_KEYPOINTS) -> list[Callable]:
  """'auto' keypoints of points [N, 3] (metres, z up), sampled from the `keypoint_domain`:
  one callable per level -> sorted indices into points, the first `coarse` farthest-point
  picks (where coarse > 0), then all `num`; one sampling, continued only as far as a level
  is asked for (the first j picks are the j-point sampling)."""
  keypoints_lib.check_registrable(points, 'auto keypoints')
  among = keypoint_domain(points, domain)
  sampler = keypoints_lib.FarthestPointSampler(points[among])
  return [lambda k=k: among[np.unique(sampler.order(k))]
          for k in ([coarse] if coarse > 0 else []) + [num]]


def coarse_keypoints(verified: bool) -> int:
  """The coarse level's keypoint count: COARSE_KEYPOINTS where the poses are verified (a
  level ends the search only on a verified pose), else 0 (one level)."""
  return COARSE_KEYPOINTS if verified else 0


def feature_levels(points: np.ndarray, keypoints: str = 'auto', descriptor: str = 'learned',
                   model=None, seed: int = 0, fpfh_max_nn: int = features.FPFH_MAX_NN,
                   coarse: int = COARSE_KEYPOINTS) -> FeatureLevels:
  """The `FeatureLevels` of one cloud [N, 3] (metres on its grid already, near the
  origin: `pipeline.Registrar` centres a far cloud first; described in float32): with
  'auto' keypoints and `coarse` > 0 two levels (`auto_levels`), else one. Nothing is
  described yet."""
  local = check_cloud(points)
  t0 = time.perf_counter()
  note = ''
  if keypoints == 'auto':
    levels = auto_levels(local, domain_of(model), coarse)
  else:
    idx, note = compute_keypoints(local, keypoints, model, seed)
    if len(idx) < 3:
      raise ValueError(f'{keypoints} keypoints: found {len(idx)} in a cloud of {len(local)} '
                       'points, 3 are needed (too sparse, or planar / collinear?)')
    levels = [idx]
  describe = lambda at: compute_descriptors(local, at, descriptor, model,
                                            fpfh_max_nn=fpfh_max_nn)
  return FeatureLevels(local, levels, describe, note,
                       seconds={'keypoints': time.perf_counter() - t0})


def local_origin(points: np.ndarray) -> np.ndarray:
  """[3] float64: zero when float32 resolves every point of `points` ([N, 3] float64
  metres) to clean.MAX_RESOLUTION, else their centroid, the origin to compute features
  around."""
  if np.spacing(np.float32(np.max(np.abs(points)))) <= clean.MAX_RESOLUTION:
    return np.zeros(3)
  return points.mean(axis=0)
