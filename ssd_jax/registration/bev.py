"""Bird's-eye-view correlation: every turn about z and every translation of two upright
scans, scored at once.

Two scans of one street taken tens of metres apart, by units with different beams, share
few local neighbourhoods that look alike, yet they share the street's layout: where
walls, poles, trees and cars stand. Each cloud becomes a top-down image of the cells
holding what rises above its ground (`structure_image`); cloud 2's image is made at every
yaw on a `YAW_STEP` circle, and the translation that lays it best on cloud 1's is the
peak of their cross-correlation, all translations at once by FFT (`search`: coarse to
fine, every other yaw on cells twice as wide first, then the best peaks at full
resolution; each cloud's ground and structure found once, `footprint`). The best distinct
peaks are candidate poses for `verification.verify`, beside RANSAC's: from the whole
scene instead of the matches. For scans whose z axis is up, as upright RANSAC. The
exhaustive correlation over yaw is the classic way to align two top-down maps (as in
RING++, Xu et al., T-RO 2023); it needs no training and no features.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import fft, ndimage

from ssd_jax.data import preprocess
from ssd_jax.registration import ransac

# Metres per image cell: the verification's ICP (1 m correspondences) converges from
# within half a cell and half a yaw step.
RESOLUTION = 0.5
# Degrees between the yaws tried (180 images).
YAW_STEP = 2.0
# Metres: each image covers this far from its cloud's centre, in x and y. Scans reach
# ~80 m, but what a sparse unit returns past ~60 m is a few rings on the ground.
EXTENT = 64.0
# Metres above the local ground: what rises from the ground (walls, poles, trunks, cars)
# is in the image; the ground itself, the same everywhere, and overhangs are not.
HEIGHT = (0.4, 6.0)
# Metres: the local ground is the lowest point within ~3 cells of this size around each
# point (cells 4 m wide: a sparse unit's rings still put ground points in most of them).
GROUND_CELL = 4.0
# Cells: the images are blurred by a Gaussian of this sigma, so that a wall seen by two
# units from two sides, a cell apart, still overlaps.
BLUR = 1.0
# Peaks kept per yaw of the coarse pass before the best distinct ones are chosen over all
# yaws (a weak true peak beside a strong wrong one still reaches the fine pass).
PEAKS_PER_YAW = 5
# Points an image is made from, at most: a denser cloud gives every ceil(N / MAX_POINTS)-th
# point, which marks the same 0.5 m cells (a wall's cell holds tens of 0.2 m grid points),
# so that a map tile's 1.5 M grid points cost what 150,000 do. Every cloud of the
# project's test sets (<= 46,000 points) is imaged whole.
MAX_POINTS = 150_000


@dataclasses.dataclass(frozen=True)
class BevResult:
  transforms: np.ndarray   # [k, 4, 4] T_12 candidates, best first (upright: turn about z)
  scores: np.ndarray       # [k] correlation at each peak (overlapping structure cells)


def _size(extent: float, resolution: float) -> int:
  return int(np.ceil(2 * extent / resolution))


def height_above_ground(points: np.ndarray) -> np.ndarray:
  """Points [N, 3] metres, z up -> [N] metres above the local ground (the lowest point
  within ~1.5 `GROUND_CELL`s)."""
  points = np.asarray(points, np.float64)
  if not len(points):
    return np.zeros(0)
  cell = np.floor(points[:, :2] / GROUND_CELL).astype(np.int64)
  cell -= cell.min(0)
  lowest = np.full(cell.max(0) + 1, np.inf)
  np.minimum.at(lowest, (cell[:, 0], cell[:, 1]), points[:, 2])
  lowest = ndimage.minimum_filter(lowest, size=3, mode='nearest')
  return points[:, 2] - lowest[cell[:, 0], cell[:, 1]]


def rising_from_ground(points: np.ndarray) -> np.ndarray:
  """Points [N, 3] metres, z up -> [N] bool: the points `HEIGHT` above the local ground
  (`height_above_ground`): walls, poles, trunks, cars."""
  height = height_above_ground(points)
  return (height > HEIGHT[0]) & (height < HEIGHT[1])


def structure_image(points: np.ndarray, resolution: float = RESOLUTION,
                    extent: float = EXTENT) -> np.ndarray:
  """Points [N, 3] metres, centred on the image -> [S, S] float32 top-down image (S =
  2 * extent / resolution, row = x, column = y): the cells holding points that rise from
  the ground (`rising_from_ground`), blurred by `BLUR` cells."""
  size = _size(extent, resolution)
  image = np.zeros((size, size), np.float32)
  points = np.asarray(points, np.float64)
  points = points[(np.abs(points[:, :2]) < extent).all(1)]
  if not len(points):
    return image
  rising = points[rising_from_ground(points)]
  return ndimage.gaussian_filter(_splat(rising[None, :, :2], resolution, size)[0], BLUR)


@dataclasses.dataclass(frozen=True)
class Footprint:
  """What the search needs of one cloud, made once in its own frame (so a cloud that
  meets many others in a batch pays for it once): its image centre and the points that
  rise from its ground, in x and y relative to that centre."""
  centre: np.ndarray   # [3] metres (z = 0)
  rising: np.ndarray   # [M, 2] metres, within reach of an image of `extent` at any yaw
  extent: float


def footprint(points: np.ndarray, extent: float = EXTENT) -> Footprint:
  """points [N, 3] metres, z up -> its `Footprint`: the image is centred on the median of
  x and y (a cloud far from the origin, or from the other); the ground is found in the
  cloud's own frame, once, and the structure turned with the cloud at each yaw."""
  points = np.asarray(points, np.float64)
  centre = np.append(np.median(points[:, :2], 0), 0.0) if len(points) else np.zeros(3)
  local = _within_reach(points, centre, extent)
  return Footprint(centre, np.ascontiguousarray(local[rising_from_ground(local)][:, :2]), extent)


def _within_reach(points: np.ndarray, centre: np.ndarray, extent: float) -> np.ndarray:
  """points [N, 3] - centre [3], only those an image of `extent` holds at some yaw, at most
  about MAX_POINTS of them (an even stride)."""
  # Only points within the image's circumscribed circle fall in it at some yaw, and each
  # image is made from the points inside it alone, so dropping the rest changes nothing.
  local = points - centre
  local = local[(local[:, :2] ** 2).sum(1) < 2 * extent ** 2]
  return local[::preprocess.even_stride(len(local), MAX_POINTS)]


def _splat(xy: np.ndarray, resolution: float, size: int) -> np.ndarray:
  """xy [B, M, 2] metres (centred) -> [B, size, size] float32 images, 1 where a point falls
  (row = x, column = y)."""
  ij = np.floor(xy / resolution).astype(np.int64) + size // 2
  inside = ((ij >= 0) & (ij < size)).all(-1)
  b = np.broadcast_to(np.arange(len(xy))[:, None], inside.shape)[inside]
  images = np.zeros((len(xy), size, size), np.float32)
  images[b, ij[..., 0][inside], ij[..., 1][inside]] = 1.0
  return images


def _blur_transfer(shape: tuple[int, int], sigma: float) -> np.ndarray:
  """The real-FFT transfer function [shape[0], shape[1] // 2 + 1] of blurring both images
  by a Gaussian of `sigma` cells: one of sigma * sqrt(2) applied to their correlation."""
  fx = np.fft.fftfreq(shape[0])[:, None]
  fy = np.fft.rfftfreq(shape[1])[None, :]
  return np.exp(-4.0 * np.pi ** 2 * sigma ** 2 * (fx ** 2 + fy ** 2)).astype(np.float32)


def _peaks(correlation: np.ndarray, count: int, radius: int) -> list[tuple[float, int, int]]:
  """The `count` highest cells of `correlation`, each `radius` cells from the others."""
  c = correlation.copy()
  found = []
  for _ in range(count):
    i, j = np.unravel_index(int(np.argmax(c)), c.shape)
    found.append((float(c[i, j]), int(i), int(j)))
    c[max(0, i - radius):i + radius + 1, max(0, j - radius):j + radius + 1] = -np.inf
  return found


def _rotations(yaws: np.ndarray) -> np.ndarray:
  """[Y, 2, 2] turns about z, applied to row vectors as xy @ R^T."""
  c, s = np.cos(yaws), np.sin(yaws)
  return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


# The coarse pass images every COARSE-th yaw at COARSE times `resolution` (an eighth of
# the work of every yaw at `resolution`). Its COARSE_PEAKS * k best distinct peaks are then
# scored at `resolution` and at the `yaw_step` yaws within (COARSE - 1) steps of theirs, in
# a window of +-REFINE cells around each: the fine search near every peak the coarse one
# found (docs/notes/speed.md: what the search costs, and that it keeps every pose).
COARSE = 2
COARSE_PEAKS = 12
REFINE = 2
# Yaws imaged per batch of the coarse pass (its FFTs run over the batch at once).
YAW_BATCH = 30


def _batched_peaks(correlation: np.ndarray, count: int, radius: int) -> list[tuple]:
  """Per image of correlation [B, P, P] (overwritten), its `count` highest cells, each
  `radius` cells from the others -> [(score, b, i, j)]."""
  batch, size = correlation.shape[0], correlation.shape[1]
  flat = correlation.reshape(batch, -1)
  found = []
  for _ in range(count):
    best = flat.argmax(1)
    for b, cell in enumerate(best):
      i, j = divmod(int(cell), size)
      found.append((float(correlation[b, i, j]), b, i, j))
      correlation[b, max(0, i - radius):i + radius + 1, max(0, j - radius):j + radius + 1] = -np.inf
  return found


def search(points1, points2, k: int = 5, yaw_step: float = YAW_STEP,
           resolution: float = RESOLUTION, extent: float = EXTENT,
           separation: tuple[float, float] = ransac.CANDIDATE_SEPARATION) -> BevResult:
  """Up to k distinct upright poses T_12 of cloud 2 in cloud 1 (points [N, 3] metres, z
  up, or their `footprint`s), best correlation first: every yaw on a `yaw_step` (degrees)
  circle, every translation within 2 * extent, at `resolution` metres, coarse to fine
  (`COARSE`). Distinct as RANSAC's candidates (`ransac.distinct_best`: `separation`
  metres or degrees apart). Deterministic."""
  if yaw_step <= 0 or resolution <= 0 or extent <= resolution:
    raise ValueError(f'BEV search needs yaw_step > 0, resolution > 0 and extent > resolution, '
                     f'got {yaw_step}, {resolution}, {extent}')
  f1, f2 = (p if isinstance(p, Footprint) else footprint(p, extent) for p in (points1, points2))
  if f1.extent != extent or f2.extent != extent:
    raise ValueError(f'footprints made for extent {f1.extent} / {f2.extent} m, searched at {extent}')
  yaws = np.deg2rad(np.arange(0.0, 360.0, yaw_step))
  turns = _rotations(yaws)
  coarse = resolution * COARSE
  size = _size(extent, coarse)
  shape = (2 * size, 2 * size)   # zero-padded: a linear, not a circular, correlation
  spectrum1 = (fft.rfft2(_splat(f1.rising[None], coarse, size)[0], s=shape)
               * _blur_transfer(shape, BLUR / COARSE))
  radius = max(1, int(round(separation[0] / coarse)))
  coarse_yaws = np.arange(0, len(yaws), COARSE)
  found = []   # (score, yaw index, shift i, shift j in coarse cells)
  for start in range(0, len(coarse_yaws), YAW_BATCH):
    part = coarse_yaws[start:start + YAW_BATCH]
    images = _splat(f2.rising[None] @ np.swapaxes(turns[part], -1, -2), coarse, size)
    correlation = fft.irfft2(spectrum1 * np.conj(fft.rfft2(images, s=shape, workers=-1)),
                             s=shape, workers=-1)
    found += [(score, part[b], i, j)
              for score, b, i, j in _batched_peaks(correlation, PEAKS_PER_YAW, radius)]
  wrap = lambda i: i if i < size else i - 2 * size   # the correlation's cells wrap
  coarse_poses = np.stack([_pose(turns[y], np.array([wrap(i), wrap(j)]) * coarse, f1, f2)
                           for _, y, i, j in found])
  chosen = ransac.distinct_best(coarse_poses, np.array([f[0] for f in found]),
                                COARSE_PEAKS * k, separation)
  # Fine: the correlation of the two blurred images is that of cloud 1's image, blurred by
  # BLUR * sqrt(2), with cloud 2's occupied cells: a sum over those cells per shift.
  fine_size = _size(extent, resolution)
  image1 = ndimage.gaussian_filter(_splat(f1.rising[None], resolution, fine_size)[0],
                                   BLUR * np.sqrt(2), mode='constant')
  # A border of 2 * REFINE zeros: every cell that some shift of the window lays on the
  # image reads inside the padded one at every shift; the others are dropped first.
  width = fine_size + 4 * REFINE
  image1 = np.pad(image1, 2 * REFINE).ravel()
  window = np.stack(np.meshgrid(np.arange(-REFINE, REFINE + 1), np.arange(-REFINE, REFINE + 1),
                                indexing='ij'), -1).reshape(-1, 2)
  offsets = window[:, 0] * width + window[:, 1]
  occupied = {}   # yaw index -> cloud 2's occupied fine cells at that yaw
  hypotheses, scores = [], []
  for n in chosen:
    _, y0, i, j = found[n]
    centre = np.array([wrap(i), wrap(j)]) * COARSE
    for y in (y0 + np.arange(1 - COARSE, COARSE)) % len(yaws):
      if y not in occupied:
        occupied[y] = np.argwhere(_splat((f2.rising @ turns[y].T)[None], resolution,
                                         fine_size)[0])
      ij = occupied[y] + centre + 2 * REFINE
      ij = ij[((ij >= REFINE) & (ij < width - REFINE)).all(1)]
      values = image1[(ij[:, 0] * width + ij[:, 1])[None] + offsets[:, None]].sum(1)   # [W]
      w = int(np.argmax(values))
      hypotheses.append(_pose(turns[y], (centre + window[w]) * resolution, f1, f2))
      scores.append(float(values[w]))
  hypotheses, scores = np.stack(hypotheses), np.asarray(scores)
  keep = ransac.distinct_best(hypotheses, scores, k, separation)
  return BevResult(hypotheses[keep], scores[keep])


def _pose(turn: np.ndarray, shift: np.ndarray, f1: Footprint, f2: Footprint) -> np.ndarray:
  """T_12 [4, 4] of image 2 turned by turn [2, 2] and moved by shift [2] metres onto
  image 1, in the clouds' frames."""
  t = np.eye(4)
  t[:2, :2] = turn
  t[:2, 3] = shift
  t[:3, 3] += f1.centre - t[:3, :3] @ f2.centre
  return t
