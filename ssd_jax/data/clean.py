"""Input checks every cloud passes before use: the shape, finite coordinates, enough
resolution in its floating-point type, not all points in one place. One-line errors
name the problem (`check_cloud` for library calls, `clean_cloud` for files, which
drops NaN rows; `units_problem` for a cloud that does not look like metres)."""

from __future__ import annotations

from absl import logging
import numpy as np
from scipy import spatial

from ssd_jax.infra import errors
from ssd_jax.data import io


class CloudDataError(errors.UserError):
  """A cloud cannot be used for training (no points left, degenerate, ...)."""


# Metres: the coarsest spacing a coordinate's floating-point type may have. A 0.2 m
# voxel grid and 1 m RANSAC inliers need the points far finer than this.
MAX_RESOLUTION = 0.01


def _resolution_problem(points: np.ndarray, dtype) -> str | None:
  """Why finite points [N, 3] cannot be held in `dtype` to MAX_RESOLUTION, or None."""
  if not len(points):
    return None
  reach = float(np.max(np.abs(points)))
  step = float(np.spacing(np.dtype(dtype).type(reach)))
  if step > MAX_RESOLUTION:
    return (f'coordinates reach {reach:.3g} m, where {np.dtype(dtype).name} resolves only '
            f'{step:.2g} m')
  return None


def check_cloud(points: np.ndarray, name: str = 'cloud', dtype=np.float32) -> np.ndarray:
  """Validate a cloud for the library's functions: [N, 3] finite `dtype` metres, or a
  ValueError naming the problem (shape, empty, NaN/Inf rows, coordinates too far from
  the origin for `dtype`; `registration.pipeline.register` centres clouds first)."""
  points = np.asarray(points)
  if points.ndim != 2 or points.shape[1] != 3:
    raise ValueError(f'{name}: expected points of shape [N, 3], got {points.shape}')
  if len(points) == 0:
    raise ValueError(f'{name}: the cloud is empty')
  if not np.issubdtype(points.dtype, np.number):
    raise ValueError(f'{name}: expected numbers, got dtype {points.dtype}')
  points = points.astype(np.promote_types(points.dtype, dtype), copy=False)
  if not np.all(np.isfinite(points)):
    raise ValueError(f'{name}: {int((~np.isfinite(points).all(1)).sum())} points have NaN/Inf '
                     'coordinates; drop them first (ssd_jax.data.clean.clean_cloud)')
  problem = _resolution_problem(points, dtype)
  if problem:
    raise ValueError(f'{name}: {problem}; subtract an offset first '
                     '(registration.pipeline.register centres each cloud in float64)')
  return points.astype(dtype, copy=False)


def clean_cloud(points: np.ndarray, name: str = 'cloud', dtype=np.float32) -> np.ndarray:
  """Drop rows with NaN/Inf coordinates; refuse empty or single-location clouds and
  coordinates that the source's or `dtype`'s precision cannot resolve to 1 cm.

  points [N, 3] -> [M, 3] `dtype` (float64 keeps far-from-origin coordinates for
  `registration.pipeline.register`, which centres them), M <= N. Dropped rows are logged.
  """
  points = np.asarray(points)
  if points.ndim != 2 or points.shape[1] != 3:
    raise CloudDataError(f'{name}: expected points of shape [N, 3], got {points.shape}')
  source = points.dtype if np.issubdtype(points.dtype, np.floating) else np.float64
  finite = np.all(np.isfinite(points), axis=1)
  if not finite.all():
    logging.warning('%s: dropped %d of %d points with NaN/Inf coordinates', name,
                    int((~finite).sum()), len(points))
    points = points[finite]
  if len(points) == 0:
    raise CloudDataError(f'{name}: no finite points')
  for kind in (source, dtype):
    problem = _resolution_problem(points, kind)
    if problem:
      hint = ('store it in float64 or nearer the origin' if kind == source else
              'centre it first, or register it with registration.pipeline.register')
      raise CloudDataError(f'{name}: {problem}; {hint}')
  points = np.asarray(points, dtype)
  if np.all(np.ptp(points, axis=0) == 0):
    raise CloudDataError(f'{name}: degenerate cloud, all {len(points)} points coincide '
                         f'at {points[0].tolist()}')
  return points


# A LiDAR cloud in metres: neighbouring points lie centimetres to a few metres apart, and
# it spans metres to kilometres. Outside these, its numbers are in other units.
MAX_SPACING = 20.0   # metres: median distance from a point to its nearest neighbour
MIN_EXTENT = 1.0     # metres: the cloud's longest side
# A cloud over WIDE_EXTENT metres across whose points lie over WIDE_SPACING apart (median)
# is a scan in centimetres: a scan's points lie 0.05-0.5 m apart and it spans up to a few
# hundred metres (in centimetres 5-50 and tens of thousands); a map that wide in metres
# is gridded finer than WIDE_SPACING.
WIDE_EXTENT = 1000.0
WIDE_SPACING = 2.0
_SPACING_SAMPLE = 5000


def units_problem(points: np.ndarray, seed: int = 0) -> str:
  """'' for a cloud points [N, 3] whose size and spacing are a LiDAR cloud's in metres,
  else one line saying what suggests other units. The spacing is that of a random
  5,000 points, scaled to all N as a surface's (by sqrt(5,000 / N))."""
  points = np.asarray(points, np.float64)
  extent = float(np.ptp(points, axis=0).max()) if len(points) else 0.0
  if extent < MIN_EXTENT:
    return (f'it spans only {extent:.3g} across, a LiDAR cloud in metres metres to '
            'kilometres: is it in kilometres? ssd_jax reads metres')
  sample = points
  if len(points) > _SPACING_SAMPLE:
    sample = points[np.random.default_rng(seed).choice(len(points), _SPACING_SAMPLE, False)]
  if len(sample) < 2:
    return ''
  distance, _ = spatial.cKDTree(sample).query(sample, k=2)
  spacing = float(np.median(distance[:, 1])) * np.sqrt(len(sample) / len(points))
  if spacing > MAX_SPACING:
    return (f'its points lie ~{spacing:.3g} apart (median), those of a LiDAR cloud in '
            'metres centimetres to a metre: is it in millimetres or centimetres? ssd_jax '
            'reads metres')
  if extent > WIDE_EXTENT and spacing > WIDE_SPACING:
    return (f'it spans {extent:.3g} across with its points ~{spacing:.3g} apart (median), '
            'a LiDAR scan in metres at most a few hundred metres with its points a '
            'metre apart at most: is it in centimetres? ssd_jax reads metres')
  return ''


def read_metres(path, fmt: str = 'auto', dtype=np.float64) -> np.ndarray:
  """The cloud of the file at `path` (`io.read_cloud`, .bin layout `fmt`) as `dtype` in the
  file's coordinates, NaN rows dropped (`clean_cloud`); one that does not look like
  metres (`units_problem`) is a CloudDataError saying so."""
  cloud = clean_cloud(io.read_cloud(path, fmt), str(path), dtype)
  problem = units_problem(cloud)
  if problem:
    raise CloudDataError(f'{path}: {problem}')
  return cloud
