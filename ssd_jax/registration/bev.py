"""Bird's-eye-view search: every turn about z and every translation of two upright
scans, scored at once.

Two scans of one street taken tens of metres apart, by units with different beams, share
few local neighbourhoods that look alike, yet they share the street's layout: where
walls, poles, trees and cars stand. Each cloud becomes top-down images of what rises
above its ground; cloud 2's are made at every yaw on a `YAW_STEP` circle, and the
translation that lays them best on cloud 1's is the peak of their cross-correlation, all
translations at once by FFT (`search`: coarse to fine, every other yaw on cells twice as
wide first, then the best peaks at full resolution; each cloud's ground found once,
`footprint`). Two scorings:

  * structure (the default): one image each of the cells holding what rises from the
    ground (`HEIGHT`), blurred by `BLUR` cells: where the two scans' walls, poles and
    cars overlap;
  * banded: cloud 2's structure 1-6 m above its ground counted in height `BANDS`, laid on
    the space cloud 1's points fill at those heights (within `REACH`, `reach_images`),
    the correlation summed over the bands. A narrow unit's wedge laid where cloud 1 saw
    only the ground, or things of another height, scores nothing; heights above the
    ground, not z, so that two scans of a sloped street still meet.

The best distinct peaks are candidate poses for `verification.verify`, beside RANSAC's:
from the whole scene instead of the matches. For scans whose z axis is up, as upright
RANSAC. The exhaustive correlation over yaw is the classic way to align two top-down maps
(as in RING++, Xu et al., T-RO 2023); it needs no training and no features.
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
# is structure (`rising_from_ground`, the verification's score); the ground itself, the
# same everywhere, and overhangs are not.
HEIGHT = (0.4, 6.0)
# Cells: the structure images are blurred by a Gaussian of this sigma, so that a wall seen
# by two units from two sides, a cell apart, still overlaps.
BLUR = 1.0
# Metres above the local ground: the bands the banded search lays cloud 2's structure in.
# Below the first a point fits the ground of any pose that keeps it level.
BANDS = (1.0, 2.5, 4.0, 6.0)
# Metres: cloud 1's points fill a band's image where they lie within this of the band's
# heights and, in x and y, within REACH of the cell (its image dilated by a disk).
BAND_MARGIN = 0.5
REACH = 0.75
# Metres: the local ground is the lowest point within ~3 cells of this size around each
# point (cells 4 m wide: a sparse unit's rings still put ground points in most of them).
GROUND_CELL = 4.0
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
  scores: np.ndarray       # [k] correlation at each peak


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


@dataclasses.dataclass(frozen=True)
class Footprint:
  """What the search needs of one cloud, made once in its own frame (so a cloud that
  meets many others in a batch pays for it once): its image centre, and its points up
  to the top band in x and y relative to that centre, with their heights above its
  ground."""
  centre: np.ndarray   # [3] metres (z = 0)
  xy: np.ndarray       # [M, 2] metres, within reach of an image of `extent` at any yaw
  height: np.ndarray   # [M] metres above the local ground (`height_above_ground`)
  extent: float

  def structure(self, banded: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Its points that rise from the ground (`HEIGHT`), or with `banded` those within
    `BANDS`, as cloud 2 -> (xy [S, 2] metres, band [S] index: 0 where not banded)."""
    if not banded:
      inside = (self.height > HEIGHT[0]) & (self.height < HEIGHT[1])
      return self.xy[inside], np.zeros(int(inside.sum()), np.int64)
    inside = (self.height >= BANDS[0]) & (self.height < BANDS[-1])
    return self.xy[inside], np.searchsorted(BANDS, self.height[inside], side='right') - 1


def footprint(points: np.ndarray, extent: float = EXTENT) -> Footprint:
  """points [N, 3] metres, z up -> its `Footprint`: the image is centred on the median of
  x and y (a cloud far from the origin, or from the other); the ground is found in the
  cloud's own frame, once, and the points turned with the cloud at each yaw."""
  points = np.asarray(points, np.float64)
  centre = np.append(np.median(points[:, :2], 0), 0.0) if len(points) else np.zeros(3)
  local = _within_reach(points, centre, extent)
  height = height_above_ground(local)
  keep = height < max(HEIGHT[1], BANDS[-1] + BAND_MARGIN)
  return Footprint(centre, np.ascontiguousarray(local[keep, :2]), height[keep], extent)


def _within_reach(points: np.ndarray, centre: np.ndarray, extent: float) -> np.ndarray:
  """points [N, 3] - centre [3], only those an image of `extent` holds at some yaw, at most
  about MAX_POINTS of them (an even stride)."""
  # Only points within the image's circumscribed circle fall in it at some yaw, and each
  # image is made from the points inside it alone, so dropping the rest changes nothing.
  local = points - centre
  local = local[(local[:, :2] ** 2).sum(1) < 2 * extent ** 2]
  return local[::preprocess.even_stride(len(local), MAX_POINTS)]


def _images(xy: np.ndarray, band: np.ndarray, bands: int, resolution: float, size: int,
            counts: bool = True) -> np.ndarray:
  """xy [B, M, 2] metres (centred), band [M] < bands -> [B, bands, size, size] float32
  images (row = x, column = y): the points in each cell of their band, or 1 where any
  falls (`counts` False)."""
  ij = np.floor(xy / resolution).astype(np.int64) + size // 2
  inside = ((ij >= 0) & (ij < size)).all(-1)
  b = np.broadcast_to(np.arange(len(xy))[:, None], inside.shape)[inside]
  flat = ((b * bands + np.broadcast_to(band, inside.shape)[inside]) * size
          + ij[..., 0][inside]) * size + ij[..., 1][inside]
  images = np.bincount(flat, minlength=len(xy) * bands * size * size).astype(np.float32)
  if not counts:
    images = np.minimum(images, 1.0, out=images)
  return images.reshape(len(xy), bands, size, size)


def reach_images(f: Footprint, resolution: float = RESOLUTION) -> np.ndarray:
  """The space a cloud's points fill, as cloud 1 -> [len(BANDS) - 1, S, S] float32 (S =
  2 * extent / resolution, row = x, column = y): per band, 1 in the cells within REACH of
  a point whose height lies within BAND_MARGIN of the band's."""
  size = _size(f.extent, resolution)
  r = int(np.ceil(REACH / resolution))
  di, dj = np.mgrid[-r:r + 1, -r:r + 1]
  disk = (di ** 2 + dj ** 2) * resolution ** 2 <= max(REACH, resolution) ** 2
  images = np.zeros((len(BANDS) - 1, size, size), np.float32)
  for band, (low, high) in enumerate(zip(BANDS[:-1], BANDS[1:])):
    near = (f.height >= low - BAND_MARGIN) & (f.height < high + BAND_MARGIN)
    filled = _images(f.xy[near][None], np.zeros(1, np.int64), 1, resolution, size)[0, 0] > 0
    images[band] = ndimage.binary_dilation(filled, structure=disk)
  return images


def _target(f: Footprint, resolution: float, banded: bool) -> np.ndarray:
  """Cloud 1's images at `resolution` -> [bands, S, S] float32: its `reach_images`, or
  (not banded) the cells of its structure blurred by BLUR * sqrt(2) cells, the blur of
  both images on the correlation."""
  if banded:
    return reach_images(f, resolution)
  xy, band = f.structure()
  occupied = _images(xy[None], band, 1, resolution, _size(f.extent, resolution), False)[0]
  return ndimage.gaussian_filter(occupied, (0, BLUR * np.sqrt(2), BLUR * np.sqrt(2)),
                                 mode='constant')


def _blur_transfer(shape: tuple[int, int], sigma: float) -> np.ndarray:
  """The real-FFT transfer function [shape[0], shape[1] // 2 + 1] of blurring both images
  by a Gaussian of `sigma` cells: one of sigma * sqrt(2) applied to their correlation."""
  fx = np.fft.fftfreq(shape[0])[:, None]
  fy = np.fft.rfftfreq(shape[1])[None, :]
  return np.exp(-4.0 * np.pi ** 2 * sigma ** 2 * (fx ** 2 + fy ** 2)).astype(np.float32)


def _rotations(yaws: np.ndarray) -> np.ndarray:
  """[Y, 2, 2] turns about z, applied to row vectors as xy @ R^T."""
  c, s = np.cos(yaws), np.sin(yaws)
  return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


# The coarse pass images every COARSE-th yaw at COARSE times `resolution` (an eighth of
# the work of every yaw at `resolution`). Its COARSE_PEAKS best distinct peaks (at least
# k) are then scored at `resolution` and at the `yaw_step` yaws within (COARSE - 1) steps
# of theirs, in a window of +-REFINE cells around each: the fine search near every peak
# the coarse one found (docs/registration.md: what the search costs).
COARSE = 2
COARSE_PEAKS = 60
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
           separation: tuple[float, float] = ransac.CANDIDATE_SEPARATION,
           banded: bool = False) -> BevResult:
  """Up to k distinct upright poses T_12 of cloud 2 in cloud 1 (points [N, 3] metres, z
  up, or their `footprint`s), best correlation first: every yaw on a `yaw_step` (degrees)
  circle, every translation within 2 * extent, at `resolution` metres, coarse to fine
  (`COARSE`), scored on the structure images or `banded` (the module's docstring).
  Distinct as RANSAC's candidates (`ransac.distinct_best`: `separation` metres or degrees
  apart). Deterministic."""
  if yaw_step <= 0 or resolution <= 0 or extent <= resolution:
    raise ValueError(f'BEV search needs yaw_step > 0, resolution > 0 and extent > resolution, '
                     f'got {yaw_step}, {resolution}, {extent}')
  f1, f2 = (p if isinstance(p, Footprint) else footprint(p, extent) for p in (points1, points2))
  if f1.extent != extent or f2.extent != extent:
    raise ValueError(f'footprints made for extent {f1.extent} / {f2.extent} m, searched at {extent}')
  xy2, band2 = f2.structure(banded)
  bands = len(BANDS) - 1 if banded else 1
  yaws = np.deg2rad(np.arange(0.0, 360.0, yaw_step))
  turns = _rotations(yaws)
  coarse = resolution * COARSE
  size = _size(extent, coarse)
  shape = (2 * size, 2 * size)   # zero-padded: a linear, not a circular, correlation
  if banded:
    spectrum1 = fft.rfft2(reach_images(f1, coarse), s=shape, workers=-1)
  else:   # the blur of both images applied to their correlation, in the frequency domain
    xy1, band1 = f1.structure()
    spectrum1 = (fft.rfft2(_images(xy1[None], band1, 1, coarse, size, False)[0], s=shape)
                 * _blur_transfer(shape, BLUR / COARSE))
  radius = max(1, int(round(separation[0] / coarse)))
  coarse_yaws = np.arange(0, len(yaws), COARSE)
  found = []   # (score, yaw index, shift i, shift j in coarse cells)
  for start in range(0, len(coarse_yaws), YAW_BATCH):
    part = coarse_yaws[start:start + YAW_BATCH]
    images = _images(xy2[None] @ np.swapaxes(turns[part], -1, -2), band2, bands, coarse, size,
                     banded)
    spectra = fft.rfft2(images, s=shape, workers=-1)
    spectra = np.conj(spectra, out=spectra)
    spectra *= spectrum1
    correlation = fft.irfft2(spectra.sum(1), s=shape, workers=-1)
    found += [(score, part[b], i, j)
              for score, b, i, j in _batched_peaks(correlation, PEAKS_PER_YAW, radius)]
  wrap = lambda i: i if i < size else i - 2 * size   # the correlation's cells wrap
  coarse_poses = np.stack([_pose(turns[y], np.array([wrap(i), wrap(j)]) * coarse, f1, f2)
                           for _, y, i, j in found])
  chosen = ransac.distinct_best(coarse_poses, np.array([f[0] for f in found]),
                                max(COARSE_PEAKS, k), separation)
  # Fine: per shift of the window, the sum of cloud 1's images over cloud 2's cells (each
  # weighted by its count where banded). A border of 2 * REFINE zeros: every cell that
  # some shift of the window lays on the image reads inside the padded one at every
  # shift; the others are dropped first.
  fine_size = _size(extent, resolution)
  width = fine_size + 4 * REFINE
  image1 = np.pad(_target(f1, resolution, banded),
                  ((0, 0), (2 * REFINE, 2 * REFINE), (2 * REFINE, 2 * REFINE))).ravel()
  window = np.stack(np.meshgrid(np.arange(-REFINE, REFINE + 1), np.arange(-REFINE, REFINE + 1),
                                indexing='ij'), -1).reshape(-1, 2)
  offsets = window[:, 0] * width + window[:, 1]
  occupied = {}   # yaw index -> cloud 2's cells at that yaw (band, i, j) and their weights
  hypotheses, scores = [], []
  for n in chosen:
    _, y0, i, j = found[n]
    centre = np.array([wrap(i), wrap(j)]) * COARSE
    for y in (y0 + np.arange(1 - COARSE, COARSE)) % len(yaws):
      if y not in occupied:
        image2 = _images((xy2 @ turns[y].T)[None], band2, bands, resolution, fine_size,
                         banded)[0]
        cells = np.argwhere(image2)
        occupied[y] = cells, image2[tuple(cells.T)]
      cells, weight = occupied[y]
      ij = cells[:, 1:] + centre + 2 * REFINE
      inside = ((ij >= REFINE) & (ij < width - REFINE)).all(1)
      flat = (cells[inside, 0] * width + ij[inside, 0]) * width + ij[inside, 1]
      values = (image1[flat[None] + offsets[:, None]] * weight[inside]).sum(1)   # [W]
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
