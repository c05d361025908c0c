"""Many pairs in one process: each cloud read, put on the grid, described and prepared once.

A sequence registers scan i to i + 1, a loop-closure back end one scan to tens of
candidates, an evaluation set each cloud 1 to many re-scans: `Registrar` keeps the last
`cache_size` clouds it met (their grid points, keypoints and descriptors, and the
`prepared.PreparedCloud` the BEV search and the verification use), so that nothing is
computed twice for one cloud, and registers a pair from them with `pipeline.estimate`
and `pipeline.verify`, as `pipeline.register` does one pair.
"""

from __future__ import annotations

import collections
import dataclasses
import os
import time
from typing import Callable

import numpy as np

from ssd_jax.registration import features as features_lib, pipeline, prepared

# Clouds kept: a KITTI-size scan costs ~5 MB here (points, normals, KD-tree, footprint).
CACHE_SIZE = 64
# What `Registrar.register` times, in order: the first four only for a cloud met first.
STAGES = ('read', 'grid', 'keypoints', 'descriptors', 'matching', 'ransac', 'bev', 'verify',
          'assess')


@dataclasses.dataclass
class _Cloud:
  points: prepared.PreparedCloud       # on the grid, float64, the file's coordinates
  features: pipeline.FeatureLevels     # keypoints and descriptors as the pairs need them
  seconds: dict                        # read / grid, once


class Registrar:
  """Registers pairs of cloud files with one setting of the pipeline.

  read(path) -> points [N, 3] float64 metres (e.g. `io.read_cloud` + `clean.clean_cloud`);
  `say(line)` gets the one-line notes (grid, keypoint fallbacks). The other arguments
  are `pipeline.register`'s: keypoints, descriptor, model (used as given; the register
  command's defaults describe with `pipeline.verified_model(model)`), seed, fpfh_max_nn,
  voxel (None: the model's grid), estimator, verify (RANSAC's candidates checked, 0:
  none) and bev (the BEV search's).
  """

  def __init__(self, read: Callable[[str], np.ndarray], *, keypoints: str = 'auto',
               descriptor: str = 'learned', model=None, seed: int = 0,
               fpfh_max_nn: int = features_lib.FPFH_MAX_NN, voxel: float | None = None,
               estimator: str = 'upright', verify: int = 10, bev: int = 5,
               say: Callable[[str], None] = print, cache_size: int = CACHE_SIZE):
    if bev > 0 and (estimator != 'upright' or verify <= 0):
      raise ValueError("the BEV search's poses turn about z only and are checked with "
                       "RANSAC's: bev needs the upright estimator and verify > 0")
    self._read, self._say = read, say
    self.keypoints, self.descriptor, self.model, self.seed = keypoints, descriptor, model, seed
    self.fpfh_max_nn, self.estimator, self.verify, self.bev = fpfh_max_nn, estimator, verify, bev
    self.voxel = pipeline.voxel_size_of(model) if voxel is None else voxel
    self._cache: collections.OrderedDict[str, _Cloud] = collections.OrderedDict()
    self._cache_size = cache_size

  def cloud(self, path: str) -> tuple[_Cloud, bool]:
    """The cloud at `path`, and whether it was computed now (False: from the cache)."""
    if path in self._cache:
      self._cache.move_to_end(path)
      return self._cache[path], False
    t0 = time.perf_counter()
    points = self._read(path)
    t1 = time.perf_counter()
    points, note = pipeline.to_grid(points, self.voxel)
    t2 = time.perf_counter()
    if note:
      self._say(f'voxel: {os.path.basename(path)}: {note}')
    f = pipeline.feature_levels(points, self.keypoints, self.descriptor, self.model,
                                self.seed, self.fpfh_max_nn,
                                pipeline.coarse_keypoints(self.verify > 0))
    if f.note:
      self._say(f'{os.path.basename(path)}: {f.note}')
    entry = _Cloud(prepared.PreparedCloud(points), f, {'read': t1 - t0, 'grid': t2 - t1})
    self._cache[path] = entry
    if len(self._cache) > self._cache_size:
      self._cache.popitem(last=False)
    return entry, True

  def register(self, path1: str, path2: str
               ) -> tuple[pipeline.Registration, pipeline.CloudFeatures, pipeline.CloudFeatures]:
    """T_12 of the pair (maps cloud 2 into cloud 1) -> (registration, features of cloud 1,
    of cloud 2). `registration.seconds` holds every stage this pair cost: reading and
    gridding a cloud met for the first time, the keypoints and descriptors it made (each
    once: a cloud's coarse level first, the rest when a pair needs them,
    `pipeline.coarse_to_fine`), matching, RANSAC, the BEV search, the verification and
    the pose's assessment (`registration.uncertainty`). A cloud that cannot be registered (too
    few points, flat) is a ValueError; a bad file the reader's error."""
    seconds = collections.defaultdict(float)
    entries = []
    for path in (path1, path2):
      entry, new = self.cloud(path)
      if new:
        for stage, s in entry.seconds.items():
          seconds[stage] += s
      entries.append(entry)
    levels = [e.features for e in entries]
    lazy = ('keypoints', 'descriptors')   # what the clouds' levels have cost until now
    before = {stage: sum(f.seconds[stage] for f in levels) for stage in lazy}
    register = lambda levels1, levels2: pipeline.coarse_to_fine(
        levels1, levels2, entries[0].points, entries[1].points, seed=self.seed,
        estimator=self.estimator, candidates=max(self.verify, 1), bev_candidates=self.bev,
        verified=self.verify > 0)
    try:
      reg, f1, f2 = register(entries[0].features.levels, entries[1].features.levels)
    except ValueError as e:
      if self.keypoints != 'iss':
        raise
      # As pipeline.register: keypoints spread over both clouds, this pair only.
      fallback = [pipeline.feature_levels(e_.points.points, 'auto', self.descriptor,
                                          self.model, self.seed, self.fpfh_max_nn,
                                          pipeline.coarse_keypoints(self.verify > 0))
                  for e_ in entries]
      self._say(f'{os.path.basename(path1)} / {os.path.basename(path2)}: {e}; '
                'registered again with farthest-point keypoints')
      reg, f1, f2 = register(fallback[0].levels, fallback[1].levels)
      levels += fallback
    for stage in lazy:
      seconds[stage] = sum(f.seconds[stage] for f in levels) - before[stage]
    reg = pipeline.assess(reg, entries[0].points, entries[1].points)
    reg.seconds = {**seconds, **reg.seconds}
    return reg, f1, f2
