"""Host-side training data: datasets of clouds and triplets that crop, subsample,
batch and prefetch (numpy, seeded).

Every batch is a pure function of (seed, step): the data-stream position is the
step itself, so a resumed run sees exactly the batches an uninterrupted run
would, with nothing extra to checkpoint.
"""

from __future__ import annotations

import collections
import concurrent.futures
import functools
import os
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np

from ssd_jax.data import clean, io, kitti, mined_pairs, rescan


def crop(points: np.ndarray, radius: float) -> np.ndarray:
  """Keep points within `radius` metres of the sensor origin (3-D distance). [N, 3] -> [M, 3]."""
  if radius <= 0:
    return points
  return points[np.einsum('ij,ij->i', points, points) < radius * radius]


def subsample_indices(rng: np.random.Generator, m: int, num_points: int) -> np.ndarray:
  """Exactly `num_points` indices into m rows: a random subset, or all rows in random
  order plus random repeats when fewer exist (docs/method.md §1). -> [num_points] int."""
  if m >= num_points:
    return rng.choice(m, num_points, replace=False)
  return np.concatenate([rng.permutation(m), rng.integers(0, m, num_points - m)])


def subsample(rng: np.random.Generator, points: np.ndarray, num_points: int) -> np.ndarray:
  """`num_points` rows of points, see `subsample_indices`. [M, 3] -> [num_points, 3]."""
  return points[subsample_indices(rng, len(points), num_points)]


def epoch_member(seed: int, position: int, n: int) -> int:
  """The item at `position` of the stream that visits n items in epochs, each a fresh
  permutation drawn from (seed, epoch)."""
  epoch, pos = divmod(position, n)
  return int(np.random.default_rng((seed, 1_000_003, epoch)).permutation(n)[pos])


class CloudDataset:
  """Training clouds from files, cleaned and cropped on first use (LRU cached).

  Args:
    files: cloud files.
    fmt: `.bin` row layout: 'auto' or a key of `io.BIN_FORMATS`.
    crop_radius: metres, <= 0 to keep everything.
    min_points: clouds with fewer points after cropping are an error.
    cache_size: clouds kept in memory.
    rotations: optional [3, 3] per file (None entries: as stored), applied on load.
  """

  def __init__(self, files: Sequence[os.PathLike], fmt: str = 'auto', crop_radius: float = 20.0,
               min_points: int = 1, cache_size: int = 512,
               rotations: Sequence[np.ndarray | None] | None = None):
    if not files:
      raise clean.CloudDataError('the dataset has no files')
    self.files = [Path(f) for f in files]
    self.rotations = list(rotations) if rotations is not None else [None] * len(self.files)
    self.fmt, self.crop_radius, self.min_points = fmt, crop_radius, min_points
    self._load = functools.lru_cache(maxsize=cache_size)(self._load_uncached)

  @classmethod
  def from_source(cls, source: str | os.PathLike, **kwargs) -> 'CloudDataset':
    """A directory, an Oxford `train.txt`, or a single file (see `io.list_clouds`)."""
    return cls(io.list_clouds(source), **kwargs)

  def __len__(self) -> int:
    return len(self.files)

  def _load_uncached(self, i: int) -> np.ndarray:
    path = self.files[i]
    pts = clean.clean_cloud(io.read_cloud(path, self.fmt), str(path))
    if self.rotations[i] is not None:
      pts = pts @ np.asarray(self.rotations[i], np.float32).T
    pts = crop(pts, self.crop_radius)
    if len(pts) < max(self.min_points, 1):
      raise clean.CloudDataError(
          f'{path}: {len(pts)} points within {self.crop_radius} m of the origin, fewer than '
          f'the {self.min_points} required; is the cloud centred on its sensor?')
    return pts

  def cloud(self, i: int) -> np.ndarray:
    """Cleaned, cropped cloud i: [M_i, 3] float32 metres."""
    return self._load(i)

  def batch(self, seed: int, step: int, batch_size: int, num_points: int,
            rows: Sequence[int] | None = None) -> np.ndarray:
    """Rows `rows` (default all) of the batch of `step`: [len(rows), num_points, 3] float32.

    Clouds are visited in epochs, each a fresh permutation drawn from
    (seed, epoch); row r subsamples with its own stream (seed, step, r), so a
    process that builds only its rows of a global batch (`distributed`) gets
    exactly what one process building the whole batch would.
    """
    rows = range(batch_size) if rows is None else rows
    out = np.empty((len(rows), num_points, 3), np.float32)
    for k, slot in enumerate(rows):
      out[k] = subsample(np.random.default_rng((seed, step, slot)),
                         self.cloud(epoch_member(seed, step * batch_size + slot, len(self))),
                         num_points)
    return out


class RescanPairDataset:
  """Each training cloud beside a second view of the same place, for the self-supervised
  objective: with chance `rate` per row, a re-scan of the cloud by a virtual unit of
  `sensors` standing `min_shift`-`max_shift` m away (`rescan.rescan_view`: its own
  standpoint, occlusion, beam pattern and voxel grid, in the cloud's frame, cropped to the
  same disk); otherwise the same subsample again (the paper's pair: a cloud and its
  turned copy). No pose or label is read: the view is made from the one cloud.

  Each cloud has `views_per_cloud` re-scans, view k of cloud i drawn from
  (seed, i, k) and cached, so a view costs its ~0.1 s once and every batch is still a
  pure function of (seed, step).
  """

  def __init__(self, files: Sequence[os.PathLike], rate: float, sensors: Sequence[str],
               min_shift: float, max_shift: float, views_per_cloud: int = 8, seed: int = 0,
               fmt: str = 'auto', crop_radius: float = 20.0, min_points: int = 1,
               cache_size: int = 4096, beams: str = 'select'):
    self.beams = beams
    self.whole = CloudDataset(files, fmt=fmt, crop_radius=0.0, min_points=min_points)
    self.clouds = CloudDataset(files, fmt=fmt, crop_radius=crop_radius, min_points=min_points)
    self.rate, self.sensors, self.views_per_cloud = rate, tuple(sensors), views_per_cloud
    self.shift, self.seed, self.crop_radius = (min_shift, max_shift), seed, crop_radius
    self._view = functools.lru_cache(maxsize=cache_size)(self._view_uncached)

  @classmethod
  def from_source(cls, source: str | os.PathLike, **kwargs) -> 'RescanPairDataset':
    return cls(io.list_clouds(source), **kwargs)

  def __len__(self) -> int:
    return len(self.clouds)

  def _view_uncached(self, i: int, k: int) -> np.ndarray:
    rng = np.random.default_rng((self.seed, 7, i, k))
    cfg = rescan.RescanConfig(min_shift=self.shift[0], max_shift=self.shift[1],
                              sensor=str(rng.choice(self.sensors)), toward_points=True,
                              min_points=RESCAN_MIN_POINTS, noise_sigma=0.0, beams=self.beams)
    try:
      view = crop(rescan.rescan_view(rng, self.whole.cloud(i), cfg), self.crop_radius)
    except ValueError:
      view = np.zeros((0, 3), np.float32)
    # A view that sees too little of the disk is no pair: the cloud is its own second view.
    return view if len(view) >= RESCAN_MIN_POINTS else self.clouds.cloud(i)

  def view(self, i: int, k: int) -> np.ndarray:
    """Re-scan k of cloud i: [M, 3] float32 metres in cloud i's frame (the cropped cloud
    itself where no standpoint sees `RESCAN_MIN_POINTS` of it)."""
    return self._view(i, k)

  def batch(self, seed: int, step: int, batch_size: int, num_points: int,
            rows: Sequence[int] | None = None) -> np.ndarray:
    """Rows `rows` (default all) of the batch of `step`: [len(rows), 2, num_points, 3]
    float32 (the cloud, its second view). Clouds are visited as `CloudDataset.batch`
    visits them; row r draws from its own stream (seed, step, r, 2)."""
    rows = range(batch_size) if rows is None else rows
    out = np.empty((len(rows), 2, num_points, 3), np.float32)
    for k, slot in enumerate(rows):
      rng = np.random.default_rng((seed, step, slot, 2))
      i = epoch_member(seed, step * batch_size + slot, len(self))
      out[k, 0] = subsample(rng, self.clouds.cloud(i), num_points)
      if rng.uniform() < self.rate:
        out[k, 1] = subsample(rng, self.view(i, int(rng.integers(self.views_per_cloud))),
                              num_points)
      else:
        out[k, 1] = out[k, 0]
    return out


# Fewer points than this of a re-scan within the crop make it no second view.
RESCAN_MIN_POINTS = 500


PAIR_WEIGHTS = ('uniform', 'distance')


class MinedPairDataset:
  """Each training cloud beside a real second scan of the same place, for the
  self-supervised objective's two-view training: with chance `rate` per row, a pair the
  miner kept (`registration.mining`, `mined_pairs.read_kept`) in either direction, scan 2
  moved into scan 1's frame by the mined T_12 and both cropped to the disk of
  `crop_radius` around scan 1's sensor (the objective then turns the second view about z
  as it turns a cloud's copy: the target rotation is still R_gt alone); otherwise a cloud
  of `files` with itself (the paper's pair). The transform is the miner's: no pose or
  label is read. A second view with fewer than `RESCAN_MIN_POINTS` points in the disk is
  replaced by the first. `weight`: PAIR_WEIGHTS, how a row picks its pair: 'uniform' (each
  alike) or 'distance' (by how far apart its scans are: the far pairs, least like the
  paper's turned copy, more often).
  """

  def __init__(self, files: Sequence[os.PathLike], pairs: Sequence[mined_pairs.MinedPair],
               rate: float, fmt: str = 'auto', crop_radius: float = 20.0, min_points: int = 1,
               cache_size: int = 1024, weight: str = 'uniform'):
    if not pairs:
      raise clean.CloudDataError('no mined pairs to train on')
    if weight not in PAIR_WEIGHTS:
      raise ValueError(f'weight must be one of {PAIR_WEIGHTS}, got {weight!r}')
    self.clouds = CloudDataset(files, fmt=fmt, crop_radius=crop_radius, min_points=min_points)
    names = sorted({p.cloud1 for p in pairs} | {p.cloud2 for p in pairs})
    self.whole = CloudDataset(names, fmt=fmt, crop_radius=0.0, min_points=min_points)
    self._index = {name: n for n, name in enumerate(names)}
    self.pairs, self.rate, self.crop_radius = list(pairs), rate, crop_radius
    apart = np.array([np.linalg.norm(p.transform[:3, 3]) for p in self.pairs])
    self._chance = (apart / apart.sum() if weight == 'distance' and apart.sum() > 0
                    else None)
    self._views = functools.lru_cache(maxsize=cache_size)(self._views_uncached)

  def __len__(self) -> int:
    return len(self.clouds)

  def _views_uncached(self, k: int, flip: bool) -> tuple[np.ndarray, np.ndarray]:
    pair = self.pairs[k]
    first, second, t = pair.cloud1, pair.cloud2, np.asarray(pair.transform, np.float64)
    if flip:
      first, second, t = second, first, np.linalg.inv(t)
    view1 = crop(self.whole.cloud(self._index[first]), self.crop_radius)
    moved = self.whole.cloud(self._index[second]).astype(np.float64) @ t[:3, :3].T + t[:3, 3]
    view2 = crop(moved.astype(np.float32), self.crop_radius)
    return view1, view2 if len(view2) >= RESCAN_MIN_POINTS else view1

  def views(self, k: int, flip: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Mined pair k (scan 2 first if `flip`): ([M1, 3], [M2, 3]) float32 metres, both in
    the first scan's frame, cropped around its sensor."""
    return self._views(k, bool(flip))

  def batch(self, seed: int, step: int, batch_size: int, num_points: int,
            rows: Sequence[int] | None = None) -> np.ndarray:
    """Rows `rows` (default all) of the batch of `step`: [len(rows), 2, num_points, 3]
    float32 (a cloud, its second view). Row r draws from its own stream (seed, step, r, 3);
    the paper's rows visit `files` as `CloudDataset.batch` does."""
    rows = range(batch_size) if rows is None else rows
    out = np.empty((len(rows), 2, num_points, 3), np.float32)
    for k, slot in enumerate(rows):
      rng = np.random.default_rng((seed, step, slot, 3))
      if rng.uniform() < self.rate:
        pick = (rng.integers(len(self.pairs)) if self._chance is None
                else rng.choice(len(self.pairs), p=self._chance))
        view1, view2 = self.views(int(pick), bool(rng.integers(2)))
        out[k, 0], out[k, 1] = subsample(rng, view1, num_points), subsample(rng, view2,
                                                                            num_points)
      else:
        i = epoch_member(seed, step * batch_size + slot, len(self.clouds))
        out[k, 0] = out[k, 1] = subsample(rng, self.clouds.cloud(i), num_points)
    return out


TRIPLET_AXES = ('scene', 'stored')
TRIPLET_POSITIVES = ('index', 'self')


def scene_rotations(files: Sequence[os.PathLike]) -> list[np.ndarray | None]:
  """The sensor -> scene rotation [3, 3] of each file that sits beside a `poses.txt`
  (KITTI-style, one row per frame, the frame number being the file's stem), else None.

  3DFeat-Net's Oxford training clouds are stored aligned to the map's axes (ENU);
  sensor-frame clouds with poses (the synthetic training set, KITTI) are rotated
  into their scene's axes to match, so that a positive differs from its anchor by
  a shift, not by the heading difference (opposite-lane passes are ~180 deg).
  """
  poses: dict[Path, np.ndarray] = {}
  out: list[np.ndarray | None] = []
  for f in map(Path, files):
    pose_file = f.parent / 'poses.txt'
    if not pose_file.is_file():
      out.append(None)
      continue
    if pose_file not in poses:
      poses[pose_file] = kitti.read_poses(pose_file)
    if not f.stem.isdigit() or int(f.stem) >= len(poses[pose_file]):
      raise clean.CloudDataError(f'{f}: beside {pose_file} ({len(poses[pose_file])} poses), a '
                           'cloud must be named by its frame number (000123.bin); use '
                           "data.triplet_axes='stored' to keep the clouds as stored")
    out.append(poses[pose_file][int(f.stem), :3, :3])
  return out


class TripletDataset:
  """3DFeat-Net's training triplets from an Oxford `train.txt` (docs/method.md §5).

  Each anchor is a cloud with at least one positive; its positive is drawn from its
  `positives`, its negative from the clouds that are neither positive, non-negative
  nor the anchor itself. Clouds load through a `CloudDataset` (cleaned, cropped,
  cached). `source`: the index file or a directory holding `train.txt`.
  `axes`: 'scene' rotates clouds that have poses into their scene's axes (see
  `scene_rotations`; Oxford's clouds have none and are already so), 'stored' keeps
  every cloud as stored. `positives`: 'index' takes them from the index; 'self' is a
  control that makes each cloud its own only positive (an independent subsample,
  augmentations and centres of the same scan), the most a positive can share with
  its anchor; negatives stay as indexed.
  """

  def __init__(self, source: str | os.PathLike, axes: str = 'scene', positives: str = 'index',
               **kwargs):
    if axes not in TRIPLET_AXES:
      raise clean.CloudDataError(f'axes must be one of {TRIPLET_AXES}, got {axes!r}')
    if positives not in TRIPLET_POSITIVES:
      raise clean.CloudDataError(f'positives must be one of {TRIPLET_POSITIVES}, got {positives!r}')
    source = Path(source)
    index = source / 'train.txt' if source.is_dir() else source
    if not index.is_file():
      raise clean.CloudDataError(f'{source}: triplet training needs a 3DFeat-Net train.txt (file | '
                           'positives | non-negatives); none found')
    entries = io.read_oxford_index(index)
    n = len(entries)
    files = [e.path for e in entries]
    rotations = scene_rotations(files) if axes == 'scene' else None
    self.clouds = CloudDataset(files, rotations=rotations, **kwargs)
    if positives == 'self':
      self.positives = [np.array([i], np.int64) for i in range(n)]
    else:
      self.positives = [np.asarray(e.positives, np.int64) for e in entries]
    self.negatives = []
    for i, e in enumerate(entries):
      bad = [j for j in (*e.positives, *e.non_negatives) if not 0 <= j < n]
      if bad:
        raise clean.CloudDataError(f'{index}: line {i + 1} refers to clouds {bad[:5]} of only {n}')
      self.negatives.append(np.setdiff1d(np.arange(n), [i, *e.positives, *e.non_negatives]))
    self.anchors = np.array([i for i in range(n) if len(self.positives[i]) and
                             len(self.negatives[i])], np.int64)
    if not len(self.anchors):
      raise clean.CloudDataError(f'{index}: no cloud has both a positive and a negative; triplets '
                           'need clouds less than ~10 m and more than ~50 m apart')

  def __len__(self) -> int:
    return len(self.anchors)

  def batch(self, seed: int, step: int, batch_size: int, num_points: int,
            rows: Sequence[int] | None = None) -> np.ndarray:
    """Rows `rows` (default all) of the triplets of `step`: [len(rows), 3, num_points, 3]
    float32 (anchor, positive, negative). Anchors are visited in seeded epochs; row r
    draws its partners and subsamples from its own stream (seed, step, r, 3)."""
    rows = range(batch_size) if rows is None else rows
    out = np.empty((len(rows), 3, num_points, 3), np.float32)
    for k, slot in enumerate(rows):
      rng = np.random.default_rng((seed, step, slot, 3))
      a = int(self.anchors[epoch_member(seed, step * batch_size + slot, len(self.anchors))])
      p = int(rng.choice(self.positives[a]))
      q = int(rng.choice(self.negatives[a]))
      for j, i in enumerate((a, p, q)):
        out[k, j] = subsample(rng, self.clouds.cloud(i), num_points)
    return out


def prefetch(make_batch, steps: range, depth: int = 4, workers: int = 2) -> Iterator[np.ndarray]:
  """Yield make_batch(step) for step in steps, computed ahead in worker threads.

  File reads and numpy release the GIL, so `depth` batches are ready before
  the jitted step asks for them. Order is preserved.
  """
  with concurrent.futures.ThreadPoolExecutor(workers, thread_name_prefix='prefetch') as pool:
    pending = collections.deque()
    it = iter(steps)
    for step in it:
      pending.append(pool.submit(make_batch, step))
      if len(pending) >= depth:
        break
    while pending:
      batch = pending.popleft().result()
      nxt = next(it, None)
      if nxt is not None:
        pending.append(pool.submit(make_batch, nxt))
      yield batch
