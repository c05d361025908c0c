"""Register two clouds, or a stream of pairs of cloud files (`Registrar`, `register_many`):
grid -> level -> features, coarse to fine -> fallback to any rotation -> back in the
clouds' frames -> ICP, assessment and a trusted pose's polish. The parts are their own
modules: the options (`options`), the per-cloud features (`cloud_features`), the per-pair
stages (`pair_stages`), levelling (`leveling`).
"""

from __future__ import annotations

import collections
import dataclasses
import os
import time
from typing import Callable, Iterable, Iterator

import numpy as np

from ssd_jax import geometry
from ssd_jax.data.clean import check_cloud
from ssd_jax.registration import cloud_features, free_space, leveling, pair_stages, prepared
from ssd_jax.registration import uncertainty
from ssd_jax.registration import options as options_lib, verdict as verdict_lib, verification

Features = cloud_features.CloudFeatures


# A pair with a scan of no ground (`Leveling.note`) is registered as given first, where its
# poses are verified: most such scans are upright (a sparse re-scan whose ground holds too
# few points, an indoor scan of walls), and a pose verified as `_settled` is as sure as any
# other pair's. Otherwise nothing may assume z is up: FPFH and RANSAC over any rotation.
UPRIGHT_NOTE = 'registered as given (z up): its verified pose is clear'
ANY_ROTATION_NOTE = 'registered with FPFH and RANSAC over any rotation'
# A pose the verdict refuses is registered again (`Options.retry`), noted as one of these
# with the first pose's reason.
RETRY_NOTES = {'structure': 'registered again with keypoints on the structure above the '
                            'ground, the first pose refused ({})',
               'learned': 'registered again with the learned descriptors sampled as the '
                          'model was trained, the first pose refused ({})',
               'fpfh': "registered again with FPFH descriptors, the learned ones' pose "
                       'refused ({})',
               'bev': "registered again with the banded BEV search's poses, the first pose "
                      'refused ({})',
               'robust': "registered again with the banded BEV search's poses aligned by a "
                         'robust ICP, the first pose refused ({})'}
# The verdict's reasons that contradict a pose, not merely doubt it (`kept_of_refused`): a
# contradicted first pose is often a wrong one laid where the other scan saw through, a
# retry's refused one a right pose of low overlap or with a near twin; a first pose refused
# as ambiguous may be the right one. The note of a retry's refused pose returned:
CONTRADICTED = ('free-space conflict', 'seen from behind')
REFUSED_RETRY_NOTE = ("every pose refused; this one, the {} try's, ranks first as the "
                      'verification ranks them')
# The features of the retries with the learned descriptors, as `_Cloud.features` keeps them.
OWN_SAMPLING = 'learned, own sampling'
ON_STRUCTURE = 'learned, keypoints on the structure'


def _settled(reg: pair_stages.Registration) -> bool:
  """Whether a verified registration's best pose is clear (`clearly_confident`)."""
  return reg.verified_fitness is not None and verification.clearly_confident(
      reg.verified_poses, reg.verified_fitness)


def kept_of_refused(verdicts: list[verdict_lib.Verdict]) -> int:
  """Which of a pair's tries to return where the verdict refused every one (`verdicts`,
  the first try's first): the first, unless the scans contradict it (`CONTRADICTED`);
  then the one ranking first as the verification ranks candidates (`free_space.ranked`:
  fitness less twice the conflict), those not contradicted first."""
  if verdicts[0].kind not in CONTRADICTED:
    return 0
  return int(free_space.ranked([v.fitness for v in verdicts], lambda k: verdicts[k].conflict,
                               lambda k: verdicts[k].kind in CONTRADICTED)[0])


def _any_rotation(options: options_lib.Options) -> options_lib.Options:
  """The options of the rotation-invariant path (clouds levelled, or left, already)."""
  return dataclasses.replace(options, descriptor='fpfh', estimator='rigid', level='none')


def register(*, target: np.ndarray, source: np.ndarray, model=None,
             options: options_lib.Options | None = None, progress=None
             ) -> tuple[pair_stages.Registration, Features, Features]:
  """Register `source` onto `target`: the transform T_12 maps source points into the
  target's frame (target = cloud 1, source = cloud 2 in every table and file).

  target [N1, 3] and source [N2, 3] metres, any float type and coordinates; model: an
  `inference.Model` where `options` need one (default `Options()`, the register
  command's). A two-cloud `Registrar`: the same path as `register_many`, its one-line
  notes (grid, levelling, keypoint fallbacks) in the registration's `notes`.
  `progress(stage)`, if given, is called as each stage starts.
  -> (registration, features of the target, features of the source).
  """
  clouds = {'cloud 1': target, 'cloud 2': source}
  notes = []
  registrar = Registrar(clouds.__getitem__, model=model, options=options, say=notes.append,
                        cache_size=2, progress=progress)
  reg, f1, f2 = registrar.register('cloud 1', 'cloud 2')
  reg.notes = notes + reg.notes
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
  registration: pair_stages.Registration | None = None  # None where the pair failed
  target_features: cloud_features.CloudFeatures | None = None
  source_features: cloud_features.CloudFeatures | None = None
  error: str = ''                           # why the pair failed, one line ('' if not)
  seconds: float = 0.0                      # wall time of this pair


@dataclasses.dataclass
class _Cloud:
  points: prepared.PreparedCloud   # on the grid, centred (`offset`), levelled (`Options.level`)
  # descriptor -> keypoints and descriptors of `points` (the options' own; ON_STRUCTURE,
  # OWN_SAMPLING and 'fpfh' once a pair is registered again, `Options.retry`)
  features: dict[str, cloud_features.FeatureLevels]
  seconds: dict                    # read, grid, level and its first level's features, once
  level: leveling.Leveling         # how `points` was levelled
  own: prepared.PreparedCloud      # on the grid, centred, not levelled (ICP, assessment)
  offset: np.ndarray               # [3] the file's coordinates less these (`local_origin`)


class Registrar:
  """Registers pairs of clouds with one setting (`Options`), keeping the last `cache_size`
  clouds it met: each read (`read(key)` -> [N, 3] float64 metres, any coordinates: a
  cloud float32 cannot resolve to MAX_RESOLUTION, e.g. in UTM, is centred on its centroid
  in float64 first, `local_origin`), put on the grid, levelled (`Options.level`),
  described (its coarse level first, the rest when a pair needs it) and prepared for the
  BEV search and the verification once. `say(line)` gets the one-line notes (grid,
  levelling, keypoint fallbacks); `progress(stage)`, if given, is called as each stage
  starts. `register` and `register_many` are a Registrar's; the register command's path."""

  def __init__(self, read: Callable[[str], np.ndarray], *, model=None,
               options: options_lib.Options | None = None, say: Callable[[str], None] = print,
               cache_size: int = CACHE_SIZE, progress: Callable[[str], None] | None = None):
    self._options = options_lib.Options() if options is None else options
    self._read, self._model, self._say = read, self._options.describing(model), say
    # `Options.retries`: name -> (features key, options, model), each learned try only where
    # the first differs from it (keypoints from every point; balls sampled otherwise).
    self._retries = {}
    for name in self._options.retries:
      if name in ('bev', 'robust'):
        if self._options.bev_candidates:
          self._retries[name] = (self._options.descriptor, dataclasses.replace(
              self._options, bev_banded=True, robust_icp=name == 'robust'), None)
      elif name == 'fpfh':
        self._retries[name] = ('fpfh', dataclasses.replace(self._options, descriptor='fpfh'),
                               None)
      elif name == 'structure' and self._options.keypoints == 'auto' and (
          self._model.keypoints != 'structure'):
        self._retries[name] = (ON_STRUCTURE, self._options,
                               dataclasses.replace(self._model, keypoints='structure'))
      elif name == 'learned' and ((model.draws, model.num_samples)
                                  != (self._model.draws, self._model.num_samples)):
        self._retries[name] = (OWN_SAMPLING, self._options, model)
    self._stage = (lambda name: None) if progress is None else progress
    self.voxel = (cloud_features.voxel_size_of(self._model) if self._options.voxel is None
                  else self._options.voxel)   # metres: the grid every cloud is put on
    self._kept: dict[str, _Cloud] = {}
    self._size = cache_size

  def levels(self, points: np.ndarray, keypoints: str, descriptor: str | None = None,
             model=None) -> cloud_features.FeatureLevels:
    """The `FeatureLevels` of points [N, 3] (on the grid, levelled) with these options'
    descriptor, or `descriptor` ('fpfh': no model; 'learned': `model`, default the
    options' own)."""
    o = self._options
    descriptor = descriptor or o.descriptor
    model = (model or self._model) if descriptor == 'learned' else None
    coarse = cloud_features.coarse_keypoints(o.verify > 0)
    return cloud_features.feature_levels(points, keypoints, descriptor, model, o.seed,
                                         o.fpfh_max_nn, coarse)

  def cloud(self, path: str) -> tuple[_Cloud, bool]:
    """The cloud at `path`, and whether it was made now (False: kept from before)."""
    if path in self._kept:
      self._kept[path] = self._kept.pop(path)   # the most recently used last
      return self._kept[path], False
    name = os.path.basename(path)
    self._stage(f'{name}: grid')
    t0 = time.perf_counter()
    points = check_cloud(self._read(path), name, np.float64)
    t1 = time.perf_counter()
    offset = cloud_features.local_origin(points)
    points, note = cloud_features.to_grid(points - offset, self.voxel)   # checked above
    t2 = time.perf_counter()
    if note:
      self._say(f'voxel: {name}: {note}')
    # Its origin is its sensor's unless moved to its centroid (`local_origin`); free space
    # is judged from it unless the options say the clouds are not in their sensors' frames.
    at_origin = not offset.any()
    own = prepared.PreparedCloud(points, at_origin and self._options.free_space)
    level, note = leveling.level_for(points, self._options.level, name,
                                     sensor_at_origin=at_origin)
    if note:
      self._say(note)
    points = level.apply(points)
    t3 = time.perf_counter()
    f = self.levels(points, self._options.keypoints)
    self._stage(f'{name}: keypoints')
    f.keypoints(0)
    if f.note:
      self._say(f'{name}: {f.note}')
    self._stage(f'{name}: descriptors')
    f.levels[0]()   # the first level's, which every pair needs
    turned = prepared.PreparedCloud(points, own.viewpoint) if level.turned else own
    self._kept[path] = _Cloud(turned,
                              {self._options.descriptor: f},
                              {'read': t1 - t0, 'grid': t2 - t1, 'level': t3 - t2,
                               **f.seconds}, level, own, offset)
    if len(self._kept) > self._size:
      del self._kept[next(iter(self._kept))]
    return self._kept[path], True

  def points(self, path: str) -> np.ndarray:
    """The cloud at `path` [N, 3] on the grid, float64 metres in its own coordinates."""
    entry, _ = self.cloud(path)
    return entry.own.points + entry.offset

  def register(self, path1: str, path2: str
               ) -> tuple[pair_stages.Registration, Features, Features]:
    """T_12 of the pair (maps cloud 2, the source, into cloud 1) -> (registration,
    features of cloud 1, of cloud 2, keypoints in the clouds' coordinates); the
    registration's `seconds` holds every stage this pair cost (`STAGES`): reading and
    gridding a cloud met first, the keypoints and descriptors it made, matching, RANSAC,
    the BEV search, the verification, ICP and the assessment. A cloud that cannot be
    registered is a ValueError, a bad file the reader's error."""
    seconds = collections.defaultdict(float)
    entries = []
    for path in (path1, path2):
      entry, new = self.cloud(path)
      if new:
        for stage, s in entry.seconds.items():
          seconds[stage] += s
      entries.append(entry)
    reg, f1, f2 = self._register(entries, seconds, f'{os.path.basename(path1)} / '
                                 f'{os.path.basename(path2)}')
    offsets = [e.offset for e in entries]
    if any(o.any() for o in offsets):   # T maps p - o2 to q - o1: q = o1 + T (p - o2)
      shift = lambda o: geometry.make_transform(np.eye(3), o)
      reg.transform = shift(offsets[0]) @ reg.transform @ shift(-offsets[1])
      f1, f2 = (dataclasses.replace(f, xyz=f.xyz.astype(np.float64) + o)
                for f, o in zip((f1, f2), offsets))
    return reg, f1, f2

  def _register(self, entries: list[_Cloud], seconds: dict, pair_name: str
                ) -> tuple[pair_stages.Registration, Features, Features]:
    """`register` in the clouds' centred coordinates."""
    groundless = any(e.level.note for e in entries)

    def any_rotation(tried: dict):
      # From the clouds kept on the grid; `tried`: the seconds of the upright try before.
      reg, f1, f2 = register(target=entries[0].own.points, source=entries[1].own.points,
                             model=self._model,
                             options=dataclasses.replace(_any_rotation(self._options),
                                                         voxel=0.0))
      spent = collections.Counter(seconds)
      spent.update(tried)
      spent.update({k: v for k, v in reg.seconds.items() if k not in ('read', 'grid')})
      reg.seconds = dict(spent)
      reg.notes = [ANY_ROTATION_NOTE] + reg.notes
      return reg, f1, f2

    if groundless and not self._options.verify:
      return any_rotation({})
    # One memo for every try: of the levelled clouds, and of the clouds as given (the
    # assessments and polishes, which judge the same poses and candidates again); one and
    # the same where neither cloud was turned.
    pair = prepared.PreparedPair(entries[0].points, entries[1].points)
    judged = (pair if all(e.points is e.own for e in entries)
              else prepared.PreparedPair(entries[0].own, entries[1].own))
    reg, f1, f2 = self._upright(entries, pair, judged, self._options, seconds, pair_name)
    if groundless:
      if not _settled(reg):
        return any_rotation(reg.seconds)
      reg.notes.append(UPRIGHT_NOTE)
    elif self._retries and not reg.verdict.registered:
      spent = collections.Counter(reg.seconds)   # every try's stages, as `any_rotation`'s
      tries = [(reg, f1, f2)]
      for name, (key, options, model) in self._retries.items():
        again, g1, g2 = self._upright(entries, pair, judged, options, seconds, pair_name,
                                      key, model, verdict_lib.RETRY_MIN_CONSTRAINT)
        spent.update(again.seconds)
        if again.verdict.registered:
          again.notes.append(RETRY_NOTES[name].format(reg.verdict.reason))
          reg, f1, f2 = again, g1, g2
          break
        again.notes.append(REFUSED_RETRY_NOTE.format(name))
        tries.append((again, g1, g2))
      else:
        reg, f1, f2 = tries[kept_of_refused([t[0].verdict for t in tries])]
      reg.seconds = dict(spent)
    reg.seconds = {**seconds, **reg.seconds}
    return reg, f1, f2

  def _upright(self, entries: list[_Cloud], pair: prepared.PreparedPair,
               judged: prepared.PreparedPair, options: options_lib.Options, seconds: dict,
               pair_name: str, key: str | None = None, model=None,
               min_constraint: float = uncertainty.MIN_CONSTRAINT
               ) -> tuple[pair_stages.Registration, Features, Features]:
    """The pair (`pair`: its levelled clouds) registered upright with `options`'
    descriptor (a learned one with `model`, default the options' own; the clouds' levels
    kept under `key`, default the descriptor, made the first time they are asked for;
    ISS keypoints RANSAC cannot sample fall back to farthest-point ones), back in the
    clouds' frames, ICP (`Options.icp`), `assess` (`min_constraint` as there) and, where
    the poses are verified and the verdict trusts the pose, `pair_stages.polish`, both on
    `judged` (the clouds as given). The levels' keypoint and descriptor seconds go to
    `seconds`."""
    key = key or options.descriptor
    for e in entries:
      if key not in e.features:
        e.features[key] = self.levels(e.points.points, options.keypoints, options.descriptor,
                                      model)
    levels = [e.features[key] for e in entries]
    lazy = ('keypoints', 'descriptors')   # what the clouds' levels have cost until now
    before = {stage: sum(f.seconds[stage] for f in levels) for stage in lazy}
    run = lambda pair_levels: pair_stages.coarse_to_fine(
        pair_levels[0].levels, pair_levels[1].levels, pair, seed=options.seed,
        estimator=options.estimator, candidates=max(options.verify, 1),
        bev_candidates=options.bev_candidates, verified=options.verify > 0,
        progress=self._stage, sampling=options.sampling, bev_banded=options.bev_banded,
        robust=options.robust_icp)
    try:
      reg, f1, f2 = run(levels)
    except ValueError as err:   # ISS keypoints that leave RANSAC nothing to sample
      if options.keypoints != 'iss':
        raise
      used = [self.levels(e.points.points, 'auto', options.descriptor, model) for e in entries]
      reg, f1, f2 = run(used)
      self._say(f'{pair_name}: {err}; registered again with {len(used[0].idx)} / '
                f'{len(used[1].idx)} farthest-point keypoints')
      levels = levels + used
    for stage in lazy:
      seconds[stage] += sum(f.seconds[stage] for f in levels) - before[stage]
    level = [e.level for e in entries]
    if any(lv.turned for lv in level):   # back in the files' frames; the kept features stay
      reg = leveling.unlevel(reg, level)
      f1, f2 = (dataclasses.replace(f, xyz=lv.undo(f.xyz)) for f, lv in zip((f1, f2), level))
    if options.icp:
      self._stage('ICP')
      t0 = time.perf_counter()
      reg.transform, reg.icp_fitness = pair_stages.refine_icp(
          entries[0].own.points, entries[1].own.points, reg.transform)
      reg.seconds['icp'] = time.perf_counter() - t0
    reg = pair_stages.assess(reg, judged, origin=-entries[0].offset,
                             min_constraint=min_constraint)
    if options.verify > 0 and reg.verdict.registered:
      reg = pair_stages.polish(reg, judged, origin=-entries[0].offset,
                               min_constraint=min_constraint)
    return reg, f1, f2


def register_many(pairs: Iterable[tuple[str, str]], read: Callable[[str], np.ndarray], *,
                  model=None, options: options_lib.Options | None = None,
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
