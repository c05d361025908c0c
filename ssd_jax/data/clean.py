"""Input checks every cloud passes before use: the shape, finite coordinates, enough
resolution in its floating-point type, not all points in one place. One-line errors
name the problem (`check_cloud` for library calls, `clean_cloud` for files, which
drops NaN rows)."""

from __future__ import annotations

from absl import logging
import numpy as np

from ssd_jax import errors


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
                     '(registration.pipeline.register centres both clouds in float64)')
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
