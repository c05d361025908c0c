"""Keypoint x descriptor rows and a per-cloud cache of their features.

A row is "keypoints+descriptor": keypoints `iss`, `random`, `auto` (farthest-point),
`structure` (farthest-point of the points above the ground, `cloud_features.keypoint_domain`)
or a checkpoint name (its detector: attention + NMS, docs/method.md §4); descriptors
`fpfh` or a checkpoint name. Checkpoint names map to training workdirs in the configs
(`checkpoints.ours`, `checkpoints.feat3dnet`). Registration and the precision
test use the same keypoints and descriptors of the same clouds, so one
`FeatureStore` computes each once.
"""

from __future__ import annotations

import collections
import dataclasses
import os
import time
from typing import Mapping, Sequence

import numpy as np

from ssd_jax import inference, pretrained
from ssd_jax.infra import errors
from ssd_jax.data import clean, io
from ssd_jax.evaluation import fingerprint
from ssd_jax.registration import cloud_features, features as features_lib, leveling, pipeline
from ssd_jax.registration import options as options_lib
from ssd_jax.registration import keypoints as keypoints_lib
from ssd_jax.registration import prepared as prepared_lib

BUILTIN_KEYPOINTS = ('iss', 'random', 'auto', 'structure')
BUILTIN_DESCRIPTORS = ('fpfh',)
NAMES = {'iss': 'ISS', 'random': 'random', 'auto': 'farthest-point',
         'structure': 'farthest-point structure', 'fpfh': 'FPFH',
         'ours': 'Ours',
         'feat3dnet': '3DFeat-Net', 'ours_detector': 'Ours (self-sup. detector)',
         'ours_run': 'Ours (this run)', 'ours_rescan': 'Ours (re-scan views)',
         'ours_mined': 'Ours (mined pairs)'}
# What a keypoint row named after a checkpoint detects with: that network's attention,
# highest first after 0.5 m non-maximum suppression (`keypoints.detect`).
_UNTRAINED_ATTENTION = "an attention the paper's CF loss never trains (it gets no gradient)"
DETECTORS = {
    'feat3dnet': "3DFeat-Net's attention, trained by its attention-weighted triplet loss",
    'ours_detector': 'the self-supervised attention, trained by CF with weights '
                     'w_ij * a_i * b_j (model.attention_in_cf)',
    'ours': _UNTRAINED_ATTENTION,
    'ours_run': _UNTRAINED_ATTENTION,
}


# Clouds x keypoint sets whose learned-descriptor clusters are kept: a pair's rows describe
# its two clouds' ISS and farthest-point keypoints with each model in turn.
CLUSTERS_KEPT = 8

# A row's part 'verify': RANSAC's distinct best poses checked against the clouds
# (`pair_stages.verify`), this many; its part 'bev' (after 'verify'): the bird's-eye-view
# search's best poses checked with them (`bev.search`), this many. A row that verifies
# runs the register command's own path (`command_options`).
VERIFY_CANDIDATES = 10
BEV_CANDIDATES = 5
# Rows named after the register command: its defaults with its model (`pretrained.DEFAULT`,
# the evaluation's checkpoint of that name) and with FPFH, and its model alone -> (label,
# descriptor, the `options.Options` fields that differ).
COMMAND_ROWS = {'register': (f'register defaults, {pretrained.DEFAULT}', pretrained.DEFAULT, {}),
                'register_fpfh': ('register defaults, FPFH', 'fpfh', {}),
                'register_descriptor': (f'descriptor alone (--verify=0 --bev=0), '
                                        f'{pretrained.DEFAULT}', pretrained.DEFAULT,
                                        {'verify': 0, 'bev': 0})}


def _parts(row: str) -> tuple[list[str], str, bool, bool]:
  """-> ([keypoints, descriptor], estimator, verify, bev), or a clear error."""
  if row in COMMAND_ROWS:
    _, desc, fields = COMMAND_ROWS[row]
    verify = fields.get('verify', VERIFY_CANDIDATES) > 0
    return ['auto', desc], 'upright', verify, verify
  parts = row.split('+')
  bev = len(parts) == 5 and parts[4] == 'bev'
  if bev:
    parts = parts[:4]
  verify = len(parts) == 4 and parts[3] == 'verify'
  if verify:
    parts = parts[:3]
  estimator = 'rigid'
  if len(parts) == 3 and parts[2] in options_lib.ESTIMATORS:
    parts, estimator = parts[:2], parts[2]
  if len(parts) != 2 or not all(parts) or (bev and estimator != 'upright'):
    raise errors.UserError(
        f'row {row!r} must be "keypoints+descriptor[+estimator[+verify[+bev]]]" (bev with '
        'the upright estimator), e.g. iss+fpfh or auto+ours+upright+verify+bev (estimators: '
        f'{", ".join(options_lib.ESTIMATORS)})')
  return parts, estimator, verify, bev


def split_row(row: str) -> tuple[str, str]:
  """'iss+fpfh' (or 'iss+fpfh+upright', 'auto+fpfh+upright+verify') -> ('iss', 'fpfh');
  a `COMMAND_ROWS` name -> ('auto', its descriptor)."""
  (kp, desc), _, _, _ = _parts(row)
  return kp, desc


def command_options(row: str, models: Mapping) -> tuple[options_lib.Options, object] | None:
  """(the register command's options, the `inference.Model` or None) a row registers
  with through `pipeline.Registrar`: a `COMMAND_ROWS` name (the model as it is: its own
  keypoint domain, an adapted export's 'structure' included), or a row that verifies its
  poses (its keypoints 'auto', all points, or 'structure' with a learned descriptor: the
  model's `keypoints`; its estimator; VERIFY_CANDIDATES; BEV_CANDIDATES with 'bev'). None
  for a row of the paper's protocol, registered from this store's features. models:
  {name: `inference.Model`} holding the row's descriptor."""
  kp, desc = split_row(row)
  if row in COMMAND_ROWS:
    fields = COMMAND_ROWS[row][2]
  elif row_verifies(row):
    if kp not in ('auto', 'structure') or (kp == 'structure' and desc in BUILTIN_DESCRIPTORS):
      raise errors.UserError(f'row {row!r}: a row that verifies registers as the register '
                             "command does, from 'auto' keypoints (or 'structure' with a "
                             'learned descriptor)')
    fields = {'estimator': row_estimator(row), 'verify': VERIFY_CANDIDATES,
              'bev': row_bev_candidates(row)}
  else:
    return None
  if desc in BUILTIN_DESCRIPTORS:
    return options_lib.Options(descriptor=desc, **fields), None
  if row in COMMAND_ROWS:   # the model's own keypoint domain, as the command takes it
    return options_lib.Options(**fields), models[desc]
  model = dataclasses.replace(models[desc], keypoints='all' if kp == 'auto' else kp)
  return options_lib.Options(**fields), model


def row_estimator(row: str) -> str:
  """The RANSAC model of a row: its third part, else 'rigid' (the paper's)."""
  return _parts(row)[1]


def row_verifies(row: str) -> bool:
  """Whether a row checks RANSAC's best poses against the clouds (its part 'verify')."""
  return _parts(row)[2]


def row_bev_candidates(row: str) -> int:
  """How many bird's-eye-view search poses a row verifies with RANSAC's (its last part
  'bev'), else 0."""
  return BEV_CANDIDATES if _parts(row)[3] else 0


def row_label(row: str) -> str:
  if row in COMMAND_ROWS:
    return COMMAND_ROWS[row][0]
  kp, desc = split_row(row)
  suffix = ', upright RANSAC' if row_estimator(row) == 'upright' else ''
  if row_verifies(row):
    suffix += ', verified'
  if row_bev_candidates(row):
    suffix += ' with BEV search'
  return f'{NAMES.get(kp, kp)} kpt + {NAMES.get(desc, desc)} desc{suffix}'


def model_names(rows: Sequence[str]) -> list[str]:
  """Checkpoint names the rows need."""
  names = set()
  for row in rows:
    kp, desc = split_row(row)
    names |= {kp} - set(BUILTIN_KEYPOINTS)
    names |= {desc} - set(BUILTIN_DESCRIPTORS)
  return sorted(names)


def load_models(checkpoints: Mapping[str, str], names: Sequence[str]):
  """checkpoints {name: shipped model name, export folder or training run} ->
  ({name: inference.Model}, {name: why it is missing})."""
  models, missing = {}, {}
  for name in names:
    path = checkpoints.get(name)
    if not path:
      missing[name] = f'no checkpoint configured for {name!r}'
      continue
    try:
      models[name] = pretrained.load(path)
    except FileNotFoundError as e:
      missing[name] = str(e)
  return models, missing


def runnable_rows(rows: Sequence[str], missing: Mapping[str, str]) -> list[str]:
  return [r for r in rows if not set(split_row(r)) & set(missing)]


def missing_reason(row: str, missing: Mapping[str, str]) -> str:
  return '; '.join(v for k, v in missing.items() if k in split_row(row))


class FeatureStore:
  """Clouds, keypoint indices and descriptors per (file, method), computed once.

  models: {checkpoint name: inference.Model}; seed: for `random` keypoints;
  fpfh_max_nn: neighbour cap of FPFH's 4 m searches; num_keypoints: farthest-point
  keypoints per cloud of the 'auto' rows (the register command's 1,024); level: 'ground'
  levels each cloud as it is read (`leveling.level`, as the register command's
  `--level=ground`: a scan tilted 3 degrees or more is turned about its sensor so that its
  ground is horizontal, one without ground or too sparse is used as it is), and the pairs'
  ground truth is then taken between the levelled clouds (`in_levelled_frames`).
  `seconds` sums the time spent per step ('keypoints:iss', 'descriptors:fpfh', ...).
  """

  def __init__(self, models: Mapping, seed: int = 0,
               fpfh_max_nn: int = features_lib.FPFH_MAX_NN, level: str = 'none',
               num_keypoints: int = keypoints_lib.FARTHEST_POINT_KEYPOINTS):
    if level not in options_lib.LEVELS:
      raise errors.UserError(f'level must be one of {options_lib.LEVELS}, got {level!r}')
    if not (isinstance(num_keypoints, int) and num_keypoints >= 3):
      raise errors.UserError(f'num_keypoints must be a whole number >= 3, got {num_keypoints!r}')
    self.num_keypoints = num_keypoints
    self.level = level
    self._levelings: dict[str, leveling.Leveling] = {}
    self.models = dict(models)
    self.seed = seed
    self.fpfh_max_nn = fpfh_max_nn
    self.fpfh_keypoints: tuple[str, ...] = ()
    self._fpfh = {}   # (path, sources) -> ({point index: row}, FPFH [M, 33]) of their keypoints
    self.seconds = collections.defaultdict(float)
    self._clouds, self._keypoints, self._descriptors = {}, {}, {}
    self._pair_memos = {}   # (path 1, path 2) -> `prepared.PreparedPair.memo`
    # The last few clouds' learned-descriptor clusters, which every model of one radius,
    # cluster size and draw count shares (`inference.neighbourhoods`): ~2 MB a cloud.
    self._clusters = collections.OrderedDict()
    self._prepared = collections.OrderedDict()

  def cloud(self, path: str | os.PathLike) -> np.ndarray:
    """xyz [N, 3] metres, NaN rows dropped."""
    key = str(path)
    if key not in self._clouds:
      points = clean.clean_cloud(io.read_cloud(path), key)
      if self.level == 'ground':
        t0 = time.perf_counter()
        self._levelings[key] = lv = leveling.level(
            points, min_tilt_deg=leveling.MIN_TILT_DEG)
        points = lv.apply(points).astype(np.float32)
        self.seconds['level'] += time.perf_counter() - t0
      self._clouds[key] = points
    return self._clouds[key]

  def leveling(self, path: str | os.PathLike) -> leveling.Leveling:
    """How `cloud(path)` was levelled (unchanged where it was not)."""
    self.cloud(path)
    return self._levelings.get(str(path), leveling.unchanged())

  def in_levelled_frame(self, path1: str | os.PathLike, path2: str | os.PathLike,
                        transform: np.ndarray) -> np.ndarray:
    """T_12 [4, 4] between the files' frames -> between the clouds as `cloud` gives them:
    L1 T_12 L2^-1 where the store levels (the same otherwise). The levelling turns each
    scan about its sensor, so RTE and the geodesic RRE of a pose are the same in either
    pair of frames."""
    if self.level == 'none':
      return transform
    return self.leveling(path1).matrix @ transform @ np.linalg.inv(self.leveling(path2).matrix)

  def in_levelled_frames(self, pairs: Sequence) -> list:
    """`registration_sets.RegistrationPair`s with T_12 `in_levelled_frame` (the same pairs
    where the store does not level)."""
    if self.level == 'none':
      return list(pairs)
    return [dataclasses.replace(p, transform=self.in_levelled_frame(p.cloud1, p.cloud2,
                                                                    p.transform))
            for p in pairs]

  def prepared(self, path: str | os.PathLike) -> prepared_lib.PreparedCloud:
    """`cloud(path)` as the BEV search and the verification use it, kept for the last
    `pipeline.CACHE_SIZE` clouds (a set pairs each cloud 1 with several re-scans)."""
    key = str(path)
    if key in self._prepared:
      self._prepared.move_to_end(key)
    else:
      self._prepared[key] = prepared_lib.PreparedCloud(self.cloud(path))
      if len(self._prepared) > pipeline.CACHE_SIZE:
        self._prepared.popitem(last=False)
    return self._prepared[key]

  def describe_fpfh_together(self, rows: Sequence[str]) -> None:
    """From now on, describe with FPFH the built-in keypoint sets of `rows` (the rows an
    evaluation runs on each of its clouds) together: FPFH at a point depends on the
    cloud only, and the neighbours' histograms of several keypoint sets are mostly the
    same points' (ISS and farthest-point keypoints together cost ~55 % of the two
    apart)."""
    self.fpfh_keypoints = tuple(sorted({kp for kp, desc in map(split_row, rows)
                                        if desc == 'fpfh' and kp in BUILTIN_KEYPOINTS}))

  def pair(self, path1: str | os.PathLike, path2: str | os.PathLike
           ) -> prepared_lib.PreparedPair:
    """Cloud 1 and cloud 2 of a pair (`prepared`), with the BEV search's poses and each
    verification ICP, kept for every pair."""
    memo = self._pair_memos.setdefault((str(path1), str(path2)), {})
    return prepared_lib.PreparedPair(self.prepared(path1), self.prepared(path2), memo)

  def keypoints(self, path: str | os.PathLike, source: str) -> np.ndarray:
    """Keypoint indices [K] into `cloud(path)`."""
    key = (str(path), source)
    if key not in self._keypoints:
      points = self.cloud(path)
      t0 = time.perf_counter()
      if source in ('auto', 'structure'):
        domain = 'all' if source == 'auto' else source
        idx = cloud_features.auto_levels(points, domain, num=self.num_keypoints)[-1]()
      elif source in BUILTIN_KEYPOINTS:
        # The protocol: a detector that finds too few keypoints fails the pair.
        idx, _ = cloud_features.compute_keypoints(points, source, seed=self.seed, fallback=False)
      else:
        idx, _ = cloud_features.compute_keypoints(points, 'learned', self._model(source))
      self.seconds[f'keypoints:{source}'] += time.perf_counter() - t0
      self._keypoints[key] = idx
    return self._keypoints[key]

  def features(self, path: str | os.PathLike, row: str) -> cloud_features.CloudFeatures:
    """Keypoints [K, 3] and descriptors [K, D] of a row on one cloud, each computed once."""
    kp, desc = split_row(row)
    key = (str(path), kp, desc)
    if key not in self._descriptors:
      points, idx = self.cloud(path), self.keypoints(path, kp)
      sources = self.fpfh_keypoints
      if desc in BUILTIN_DESCRIPTORS and len(sources) > 1 and kp in sources:
        describe = lambda at: self._fpfh_together(path, sources, at)
      elif desc in BUILTIN_DESCRIPTORS:
        describe = lambda at: cloud_features.compute_descriptors(points, at, desc,
                                                                 fpfh_max_nn=self.fpfh_max_nn)
      else:
        describe = lambda at, model=self._model(desc): inference.describe(
            model, points, points[at], clusters=self._clusters_of(path, model, at))
      t0 = time.perf_counter()
      self._descriptors[key] = cloud_features.CloudFeatures(points[idx], describe(idx), {})
      self.seconds[f'descriptors:{desc}'] += time.perf_counter() - t0
    return self._descriptors[key]

  def _fpfh_together(self, path: str | os.PathLike, sources: tuple[str, ...],
                     at: np.ndarray) -> np.ndarray:
    """FPFH [len(at), 33] at cloud(path)[at], computed with every keypoint set of
    `sources` of the cloud the first time (alone on a cloud described on the search grid,
    `features.searched_on_grid`)."""
    key = (str(path), sources)
    if features_lib.searched_on_grid(self.cloud(path)):   # FPFH there depends on the set
      return cloud_features.compute_descriptors(self.cloud(path), at, 'fpfh',
                                                fpfh_max_nn=self.fpfh_max_nn)
    if key not in self._fpfh:
      together = np.unique(np.concatenate([self.keypoints(path, s) for s in sources]))
      d = cloud_features.compute_descriptors(self.cloud(path), together, 'fpfh',
                                             fpfh_max_nn=self.fpfh_max_nn)
      self._fpfh[key] = ({int(i): n for n, i in enumerate(together)}, d)
    rows, d = self._fpfh[key]
    return d[[rows[int(i)] for i in at]]

  def _clusters_of(self, path: str | os.PathLike, model, at: np.ndarray):
    """`inference.neighbourhoods` of `model` at cloud(path)[at], kept for the last
    CLUSTERS_KEPT (cloud, keypoints, setting)s."""
    key = (str(path), model.radius, model.num_samples, model.draws, np.asarray(at).tobytes())
    if key in self._clusters:
      self._clusters.move_to_end(key)
    else:
      points = self.cloud(path)
      self._clusters[key] = inference.neighbourhoods(model, points, points[at])
      if len(self._clusters) > CLUSTERS_KEPT:
        self._clusters.popitem(last=False)
    return self._clusters[key]

  def file_digests(self) -> dict[str, dict[str, str]]:
    """{stage: {file: digest}} of what this store computed: the clouds as read, the
    keypoints of each source, the descriptors of each row. The stores of several
    processes (each with its share of the files) merge by updating these dicts."""
    out = {'clouds (as read)': {k: fingerprint.digest([v]) for k, v in self._clouds.items()}}
    for (path, source), idx in self._keypoints.items():
      out.setdefault(f'keypoints: {source}', {})[path] = fingerprint.digest([idx])
    for (path, kp, desc), f in self._descriptors.items():
      out.setdefault(f'descriptors: {kp}+{desc}', {})[path] = fingerprint.digest(
          [f.descriptors])
    return out

  def fingerprints(self, file_digests: Mapping[str, Mapping[str, str]] | None = None,
                   ) -> dict[str, str]:
    """A digest per stage (of `file_digests`, default this store's own), over the files
    in sorted order, and one of each model's weights."""
    file_digests = self.file_digests() if file_digests is None else file_digests
    order = lambda stage: (('clouds', 'keypoints', 'descriptors').index(stage.split()[0].rstrip(':')),
                           stage)
    out = {}
    for stage in sorted(file_digests, key=order):
      files = file_digests[stage]   # the paths order the digests but are not hashed
      out[stage] = fingerprint.digest(
          [np.frombuffer(''.join(files[p] for p in sorted(files)).encode(), np.uint8)])
    for name, model in sorted(self.models.items()):
      out[f'weights: {name}'] = fingerprint.params_digest(model.variables)
    return out

  def _model(self, name: str):
    if name not in self.models:
      raise KeyError(f'no model loaded for {name!r}; loaded: {sorted(self.models)}')
    return self.models[name]
