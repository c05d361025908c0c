"""Keypoint detectors (host side). Each returns sorted indices into the cloud."""

from __future__ import annotations

import numpy as np
from scipy import spatial

from ssd_jax.data import preprocess

# docs/method.md §4: the parameters of the paper's ISS keypoints.
ISS_PARAMS = dict(salient_radius=1.0, non_max_radius=0.5, gamma_21=0.975, gamma_32=0.975,
                  min_neighbors=7)


def iss(points: np.ndarray, **overrides) -> np.ndarray:
  """Intrinsic Shape Signature keypoints (Open3D) of points [N, 3] metres -> indices [K].

  Open3D returns keypoint coordinates in a thread-dependent order; they are mapped
  back to indices and sorted, so the result is deterministic.
  """
  import open3d as o3d  # pylint: disable=g-import-not-at-top
  params = {**ISS_PARAMS, **overrides}
  pts = np.asarray(points, np.float64)
  kp = o3d.geometry.keypoint.compute_iss_keypoints(
      o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts)), **params)
  kp = np.asarray(kp.points)
  if len(kp) == 0:
    return np.zeros(0, np.int64)
  _, idx = spatial.cKDTree(pts).query(kp)
  return np.unique(idx)


def random_keypoints(rng: np.random.Generator, num_points: int, k: int) -> np.ndarray:
  """k distinct random indices (all when fewer), sorted."""
  return np.sort(rng.choice(num_points, min(k, num_points), replace=False))


# Farthest-point sampling computes N distances per pick. Above this many points it samples
# an even stride of them instead: picks metres apart lose nothing that a stride of a 0.2 m
# grid drops, and a map tile's 1.5 M grid points cost what 200,000 do. Every cloud of the
# project's test sets (<= 46,000 points) is sampled whole.
FPS_MAX_POINTS = 200_000


class FarthestPointSampler:
  """Farthest-point sampling of points [N, 3] (of every ceil(N / max_points)-th one) from
  the point nearest the centroid (deterministic), picked only as far as asked: `order(k)`
  continues from the picks made so far."""

  def __init__(self, points: np.ndarray, max_points: int = FPS_MAX_POINTS):
    self._stride = preprocess.even_stride(len(points), max_points)
    pts = np.asarray(points[::self._stride], np.float64)
    self._pts = pts
    # Per coordinate, in preallocated buffers: the same sums, in the same order, as
    # np.sum((pts - p) ** 2, axis=1) (bit-identical picks), ~9x faster: no temporaries.
    self._xyz = [np.ascontiguousarray(pts[:, c]) for c in range(3)]
    self._dist = np.full(len(pts), np.inf)
    self._d, self._t = np.empty(len(pts)), np.empty(len(pts))
    self._chosen: list[int] = []

  def order(self, k: int) -> np.ndarray:
    """The first min(k, N) picks, indices into the points, in the order picked: the first
    j of them are the j-point sampling, an even spread at every j."""
    pts, dist, d, t = self._pts, self._dist, self._d, self._t
    k = min(k, len(pts))
    while len(self._chosen) < k:
      if self._chosen:
        i = int(np.argmax(dist))
      else:
        i = int(np.argmin(np.sum((pts - pts.mean(0)) ** 2, axis=1)))
      self._chosen.append(i)
      p = pts[i]
      np.subtract(self._xyz[0], p[0], out=d)
      np.multiply(d, d, out=d)
      for c in (1, 2):
        np.subtract(self._xyz[c], p[c], out=t)
        np.multiply(t, t, out=t)
        np.add(d, t, out=d)
      np.minimum(dist, d, out=dist)
    return np.asarray(self._chosen[:k], np.int64) * self._stride


def farthest_point_order(points: np.ndarray, k: int,
                         max_points: int = FPS_MAX_POINTS) -> np.ndarray:
  """`FarthestPointSampler(points, max_points).order(k)`: indices [min(k, N)] in the
  order picked."""
  return FarthestPointSampler(points, max_points).order(k)


def farthest_point_keypoints(points: np.ndarray, k: int,
                             max_points: int = FPS_MAX_POINTS) -> np.ndarray:
  """k points spread evenly over the cloud (`farthest_point_order`) -> sorted indices
  [min(k, N)]."""
  return np.unique(farthest_point_order(points, k, max_points))


# `iss_with_fallbacks`: fewer ISS keypoints than this is too few to register a pair
# reliably (RANSAC needs tens of correct matches among them), so the next detector is tried.
ENOUGH_KEYPOINTS = 64
ISS_SCALES = (2.0, 4.0)        # ISS radii, times the paper's, tried in turn on sparse clouds
FARTHEST_POINT_KEYPOINTS = 1024
MIN_RELIEF = 0.05   # metres: a cloud flatter than this has no 3-D structure to register by


def check_registrable(points: np.ndarray, what: str = 'keypoints') -> None:
  """Refuse, with a one-line ValueError, a cloud [N, 3] (metres) that no keypoints can
  register: fewer than `ENOUGH_KEYPOINTS` points, or flat (the smallest principal
  standard deviation under `MIN_RELIEF`: a plane slides over itself)."""
  pts = np.asarray(points, np.float64)
  if len(pts) < ENOUGH_KEYPOINTS:
    raise ValueError(f'{what}: found a cloud of {len(pts)} points, {ENOUGH_KEYPOINTS} are '
                     'needed (too sparse?)')
  relief = float(np.sqrt(max(np.linalg.eigvalsh(np.cov(pts.T))[0], 0.0)))
  if relief < MIN_RELIEF:
    raise ValueError(f'{what}: found no relief: all {len(pts)} points lie within '
                     f'{relief:.3f} m (1 sigma) of a plane, a degenerate scene')


def point_spacing(points: np.ndarray, sample: int = 2000) -> float:
  """Median distance (metres) from a point to its nearest neighbour, over up to `sample`
  evenly strided points of points [N, 3]."""
  pts = np.asarray(points, np.float64)
  if len(pts) < 2:
    return float('nan')
  probe = pts[::max(1, len(pts) // sample)]
  dist, _ = spatial.cKDTree(pts).query(probe, k=2)
  return float(np.median(dist[:, 1]))


def iss_with_fallbacks(points: np.ndarray) -> tuple[np.ndarray, str]:
  """ISS that does not give up on a sparse cloud: the paper's radii; where that finds
  fewer than `ENOUGH_KEYPOINTS` (a 16-beam unit, a small crop), ISS with its radii scaled
  up (`ISS_SCALES`, so that each neighbourhood holds as many points as in a 64-beam scan);
  then `FARTHEST_POINT_KEYPOINTS` farthest-point keypoints, which need no structure; a
  cloud that `check_registrable` refuses is a ValueError.
  points [N, 3] metres -> (indices [K], '' or a one-line note of the fallback used)."""
  idx = iss(points)
  if len(idx) >= ENOUGH_KEYPOINTS:
    return idx, ''
  check_registrable(points, 'iss keypoints')   # no fallback registers these either
  found = (f'ISS found {len(idx)} keypoints in {len(points)} points '
           f'(point spacing {point_spacing(points):.2f} m)')
  for scale in ISS_SCALES:
    scaled = iss(points, **{k: v * scale for k, v in ISS_PARAMS.items() if k.endswith('radius')})
    if len(scaled) >= ENOUGH_KEYPOINTS:
      return scaled, f'{found}; used ISS at {scale:g}x its radii: {len(scaled)} keypoints'
  fps = farthest_point_keypoints(points, FARTHEST_POINT_KEYPOINTS)
  return fps, f'{found}; used {len(fps)} farthest-point keypoints'
