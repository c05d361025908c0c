"""Bird's-eye-view correlation: every turn about z and every translation of two upright
scans, scored at once.

Two scans of one street taken tens of metres apart, by units with different beams, share
few local neighbourhoods that look alike (a descriptor's nearest neighbour is the true
partner for ~1 % of keypoints 30-40 m apart, docs/cross_sensor.md), yet they share the
street's layout: where walls, poles, trees and cars stand. Seen from above, what rises
above the ground is nearly the same for any unit that hits it at all. Each cloud becomes
a top-down image of the cells holding such points (`structure_image`); cloud 2's image is
made at every yaw on a `YAW_STEP` circle, and the translation that lays it best on cloud
1's is the peak of their cross-correlation, all translations at once by FFT (`search`).
The best distinct peaks are candidate poses for `verification.verify`, which refines
each by ICP and keeps the one the clouds agree with: the same role as RANSAC's candidates,
from the whole scene instead of the matches. For scans whose z axis is up (vehicles,
tripods), as upright RANSAC.

The exhaustive correlation over yaw is the classic way to align two top-down maps (as in
Fourier-based and Radon-based LiDAR place recognition, e.g. RING++, Xu et al., T-RO 2023);
it needs no training and no features.
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
# Peaks kept per yaw before the best distinct ones are chosen over all yaws.
PEAKS_PER_YAW = 3
# Points an image is made from, at most: a denser cloud gives every ceil(N / MAX_POINTS)-th
# point, which marks the same 0.5 m cells (a wall's cell holds tens of 0.2 m grid points),
# so that a map tile's 1.5 M grid points cost 180 images of 150,000. Every cloud of the
# project's test sets (<= 46,000 points) is imaged whole.
MAX_POINTS = 150_000


@dataclasses.dataclass(frozen=True)
class BevResult:
  transforms: np.ndarray   # [k, 4, 4] T_12 candidates, best first (upright: turn about z)
  scores: np.ndarray       # [k] correlation at each peak (overlapping structure cells)


def _size(extent: float, resolution: float) -> int:
  return int(np.ceil(2 * extent / resolution))


def rising_from_ground(points: np.ndarray) -> np.ndarray:
  """Points [N, 3] metres, z up -> [N] bool: the points `HEIGHT` above the local ground
  (the lowest point within ~1.5 `GROUND_CELL`s): walls, poles, trunks, cars."""
  points = np.asarray(points, np.float64)
  if not len(points):
    return np.zeros(0, bool)
  cell = np.floor(points[:, :2] / GROUND_CELL).astype(np.int64)
  cell -= cell.min(0)
  lowest = np.full(cell.max(0) + 1, np.inf)
  np.minimum.at(lowest, (cell[:, 0], cell[:, 1]), points[:, 2])
  lowest = ndimage.minimum_filter(lowest, size=3, mode='nearest')
  height = points[:, 2] - lowest[cell[:, 0], cell[:, 1]]
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
  ij = np.floor(rising[:, :2] / resolution).astype(np.int64) + size // 2
  ij = ij[((ij >= 0) & (ij < size)).all(1)]
  image[ij[:, 0], ij[:, 1]] = 1.0
  return ndimage.gaussian_filter(image, BLUR)


def _turn(yaw: float) -> np.ndarray:
  c, s = np.cos(yaw), np.sin(yaw)
  return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _within_reach(points: np.ndarray, centre: np.ndarray, extent: float) -> np.ndarray:
  """points [N, 3] - centre [3], only those an image of `extent` holds at some yaw, at most
  about MAX_POINTS of them (an even stride)."""
  # Only points within the image's circumscribed circle fall in it at some yaw, and each
  # image is made from the points inside it alone, so dropping the rest changes nothing.
  local = points - centre
  local = local[(local[:, :2] ** 2).sum(1) < 2 * extent ** 2]
  return local[::preprocess.even_stride(len(local), MAX_POINTS)]


def _peaks(correlation: np.ndarray, count: int, radius: int) -> list[tuple[float, int, int]]:
  """The `count` highest cells of `correlation`, each `radius` cells from the others."""
  c = correlation.copy()
  found = []
  for _ in range(count):
    i, j = np.unravel_index(int(np.argmax(c)), c.shape)
    found.append((float(c[i, j]), int(i), int(j)))
    c[max(0, i - radius):i + radius + 1, max(0, j - radius):j + radius + 1] = -np.inf
  return found


def search(points1: np.ndarray, points2: np.ndarray, k: int = 5, yaw_step: float = YAW_STEP,
           resolution: float = RESOLUTION, extent: float = EXTENT,
           separation: tuple[float, float] = ransac.CANDIDATE_SEPARATION) -> BevResult:
  """Up to k distinct upright poses T_12 of cloud 2 [N2, 3] in cloud 1 [N1, 3] (metres, z
  up), best correlation first: every yaw on a `yaw_step` (degrees) circle, every
  translation within 2 * extent, at `resolution` metres. Distinct as RANSAC's candidates
  (`ransac.distinct_best`: `separation` metres or degrees apart). Deterministic."""
  if yaw_step <= 0 or resolution <= 0 or extent <= resolution:
    raise ValueError(f'BEV search needs yaw_step > 0, resolution > 0 and extent > resolution, '
                     f'got {yaw_step}, {resolution}, {extent}')
  p1, p2 = (np.asarray(p, np.float64) for p in (points1, points2))
  # Each image is centred on its own cloud (clouds far from the origin, or from each other).
  c1 = np.append(np.median(p1[:, :2], 0), 0.0)
  c2 = np.append(np.median(p2[:, :2], 0), 0.0)
  size = _size(extent, resolution)
  shape = (2 * size, 2 * size)   # zero-padded: a linear, not a circular, correlation
  p1, p2 = _within_reach(p1, c1, extent), _within_reach(p2, c2, extent)
  spectrum1 = fft.rfft2(structure_image(p1, resolution, extent), s=shape)
  yaws = np.deg2rad(np.arange(0.0, 360.0, yaw_step))
  radius = max(1, int(round(separation[0] / resolution)))
  hypotheses, scores = [], []
  for yaw in yaws:
    turn = _turn(yaw)
    image2 = structure_image(p2 @ turn.T, resolution, extent)
    correlation = fft.irfft2(spectrum1 * np.conj(fft.rfft2(image2, s=shape)), s=shape)
    for score, i, j in _peaks(correlation, PEAKS_PER_YAW, radius):
      # Cell (i, j) of the correlation: image 2 moved by (i, j) cells (wrapped) onto image 1.
      shift = np.array([i if i < size else i - 2 * size,
                        j if j < size else j - 2 * size, 0.0]) * resolution
      t = np.eye(4)
      t[:3, :3] = turn
      t[:3, 3] = shift + c1 - turn @ c2
      hypotheses.append(t)
      scores.append(score)
  hypotheses, scores = np.stack(hypotheses), np.asarray(scores)
  chosen = ransac.distinct_best(hypotheses, scores, k, separation)
  return BevResult(hypotheses[chosen], scores[chosen])
