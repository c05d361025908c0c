"""Point-to-plane ICP against a target surface made once per cloud.

The target's KD-tree and normals are what ICP spends on a cloud before its first
iteration; a verification refines up to 15 candidate poses against one cloud 1, and a
batch meets each cloud in many pairs, so `Surface` keeps them and `point_to_plane`
reuses them (Open3D's `registration_icp` builds its KD-tree anew on every call), and a
normal is computed only for the points that become a correspondence. The rule is Open3D's `TransformationEstimationPointToPlane` with `ICPConvergenceCriteria`:
nearest neighbours within the correspondence distance, one Gauss-Newton step of the
linearised point-to-plane residual (n_q . (R p + t - q)) per iteration, the update
applied on the left, and a stop when neither the fitness nor the inlier RMSE changes by
1e-6 (Rusinkiewicz & Levoy, "Efficient variants of the ICP algorithm", 3DIM 2001).
"""

from __future__ import annotations

import numpy as np
from scipy import spatial

# Normals: the plane of each point's 30 nearest neighbours within 1 m (Open3D's hybrid
# search, as every ICP of the project has used).
NORMAL_RADIUS = 1.0
NORMAL_NEIGHBOURS = 30
RELATIVE_CHANGE = 1e-6
# Nearest-neighbour queries of at least this many points run on every core: below it,
# waking the pool costs more than it saves (scipy's cKDTree on the 2-core VM: 1.5x faster
# at 5,000 points, break-even near 3,000, 1.4x slower at 1,000). Same neighbours either way.
PARALLEL_QUERY_POINTS = 4000


class Surface:
  """A target cloud for ICP: points [N, 3] metres and their KD-tree, and unit normals
  computed on first use of each point (`normals_at`): the candidates' correspondences
  touch a fraction of a scan, and a batch meets most clouds as a target once."""

  def __init__(self, points: np.ndarray):
    self.points = np.ascontiguousarray(points, np.float64)
    self.tree = spatial.cKDTree(self.points)
    self._normals = np.zeros((len(self.points), 3))
    self._known = np.zeros(len(self.points), bool)

  def normals_at(self, idx: np.ndarray) -> np.ndarray:
    """Unit normals [M, 3] of points[idx] (`normals`)."""
    need = np.unique(idx[~self._known[idx]])
    if len(need):
      self._normals[need] = normals(self.points, self.tree, need)
      self._known[need] = True
    return self._normals[idx]


def normals(points: np.ndarray, tree: spatial.cKDTree | None = None,
            at: np.ndarray | None = None, radius: float = NORMAL_RADIUS,
            max_nn: int = NORMAL_NEIGHBOURS) -> np.ndarray:
  """points [N, 3] metres -> unit normals [N, 3] (of points[at] [M, 3] where given): the
  least principal axis of each point's `max_nn` nearest neighbours within `radius`
  (itself included); (0, 0, 1) where fewer than 3 are found. The sign is arbitrary
  (point-to-plane residuals do not see it)."""
  points = np.asarray(points, np.float64)
  tree = spatial.cKDTree(points) if tree is None else tree
  query = points if at is None else points[at]
  k = min(max_nn, len(points))
  out = np.tile([0.0, 0.0, 1.0], (len(query), 1))
  if k < 3:
    return out
  dist, idx = tree.query(query, k=k, distance_upper_bound=radius, workers=-1)
  found = np.isfinite(dist)                                          # [M, k]
  count = found.sum(1)
  n = np.maximum(count, 1).astype(np.float64)
  # Per coordinate, contiguous [M, k] (twice the speed of [M, k, 3] slices): neighbours
  # relative to their point (precision far from the origin), 0 where missing (the tree's
  # index len(points) then, a 0 appended).
  rel = []
  for i in range(3):
    column = np.append(points[:, i], 0.0)[idx] - query[:, i, None]
    column *= found
    rel.append(column)
  mean = [r.sum(1) / n for r in rel]
  cov = np.empty((len(query), 3, 3))
  for i in range(3):
    for j in range(i, 3):
      cov[:, i, j] = cov[:, j, i] = (np.einsum('nk,nk->n', rel[i], rel[j]) / n
                                     - mean[i] * mean[j])
  ok = count >= 3
  out[ok] = least_axis(cov[ok])
  return out


def least_axis(cov: np.ndarray) -> np.ndarray:
  """Symmetric positive semi-definite cov [N, 3, 3] -> unit eigenvectors [N, 3] of the
  smallest eigenvalue, in closed form (the trigonometric eigenvalues of a 3 x 3, then the
  widest cross product of two rows of cov - lambda I): ~10x np.linalg.eigh's speed."""
  scale = np.abs(cov).reshape(len(cov), 9).max(1)
  a = cov / np.where(scale > 0, scale, 1.0)[:, None, None]
  q = np.trace(a, axis1=1, axis2=2) / 3.0
  off = a[:, 0, 1] ** 2 + a[:, 0, 2] ** 2 + a[:, 1, 2] ** 2
  p = np.sqrt(np.maximum(((a[:, 0, 0] - q) ** 2 + (a[:, 1, 1] - q) ** 2 + (a[:, 2, 2] - q) ** 2
                          + 2.0 * off) / 6.0, 1e-30))
  b = (a - q[:, None, None] * np.eye(3)) / p[:, None, None]
  phi = np.arccos(np.clip(np.linalg.det(b) / 2.0, -1.0, 1.0)) / 3.0
  smallest = q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0)
  m = a - smallest[:, None, None] * np.eye(3)
  crosses = np.stack([np.cross(m[:, 0], m[:, 1]), np.cross(m[:, 0], m[:, 2]),
                      np.cross(m[:, 1], m[:, 2])], 1)                  # [N, 3, 3]
  norms = np.linalg.norm(crosses, axis=2)
  best = norms.argmax(1)
  vector = crosses[np.arange(len(cov)), best]
  length = norms[np.arange(len(cov)), best]
  # Isotropic (all eigenvalues equal): any axis is least; z, as for too few neighbours.
  return np.where(length[:, None] > 1e-12, vector / np.maximum(length, 1e-300)[:, None],
                  np.array([0.0, 0.0, 1.0]))


def surface(points: np.ndarray) -> Surface:
  """points [N, 3] metres -> the `Surface` ICP aligns to."""
  return Surface(points)


def _increment(x: np.ndarray) -> np.ndarray:
  """[4, 4] of a Gauss-Newton step x = (rx, ry, rz, tx, ty, tz): R = Rz Ry Rx, as Open3D."""
  (cx, cy, cz), (sx, sy, sz) = np.cos(x[:3]), np.sin(x[:3])
  t = np.eye(4)
  t[:3, :3] = [[cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx],
               [sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx],
               [-sy, cy * sx, cy * cx]]
  t[:3, 3] = x[3:]
  return t


# The robust ICP's Geman-McClure scale, a share of the correspondence distance: two scans
# sharing a fifth of their view pair most of cloud 2's points with a surface within 1 m that
# is not theirs (a hedge before a wall, the far side of a street), and squared residuals let
# those drag a right pose 17 degrees off on a real far pair; at a quarter of the distance a
# residual of half of it weighs 0.04 (docs/notes/real_drives.md: the robust ICP).
ROBUST_SCALE = 0.25


def geman_mcclure(residual: np.ndarray, scale: float) -> np.ndarray:
  """Weights [C] of point-to-plane residuals [C] (metres) under a Geman-McClure kernel of
  `scale` metres: (s^2 / (s^2 + r^2))^2, 1 at r = 0 (Open3D's GMLoss with k = s^2, up to a
  constant factor, which a weighted least squares step does not see)."""
  s2 = scale ** 2
  return (s2 / (s2 + residual ** 2)) ** 2


def correspondences(target: Surface, moved: np.ndarray, distance: float):
  """moved [M, 3] -> (has a partner [M] bool, partner index [M], distance [M]): the
  nearest target point within `distance` metres."""
  workers = -1 if len(moved) >= PARALLEL_QUERY_POINTS else 1
  dist, idx = target.tree.query(moved, distance_upper_bound=distance, workers=workers)
  found = np.isfinite(dist)
  return found, np.where(found, idx, 0), dist


def point_to_plane(target: Surface, source: np.ndarray, transform: np.ndarray,
                   distances=(1.0,), iterations: int = 30,
                   robust: bool = False) -> tuple[np.ndarray, float]:
  """ICP of source points [M, 3] onto `target` from T_12 [4, 4], with correspondences
  within each of `distances` (metres) in turn, at most `iterations` steps each ->
  (T_12, fitness: share of source points with a partner at the last distance). `robust`:
  each step weighs the residuals by `geman_mcclure` at ROBUST_SCALE of the distance
  (iteratively reweighted least squares), so that points paired with a surface that is
  not theirs do not drag the pose."""
  source = np.asarray(source, np.float64)
  t = np.array(transform, np.float64)
  fitness = 0.0
  if not len(source):
    return t, fitness
  for distance in distances:
    previous = None
    for step in range(iterations + 1):
      moved = source @ t[:3, :3].T + t[:3, 3]
      found, idx, dist = correspondences(target, moved, distance)
      fitness = float(found.mean())
      rmse = float(np.sqrt(np.mean(dist[found] ** 2))) if found.any() else 0.0
      if previous is not None and (abs(previous[0] - fitness) < RELATIVE_CHANGE
                                   and abs(previous[1] - rmse) < RELATIVE_CHANGE):
        break
      previous = (fitness, rmse)
      if found.sum() < 6 or step == iterations:
        break
      p, q, n = moved[found], target.points[idx[found]], target.normals_at(idx[found])
      jacobian = np.concatenate([np.cross(p, n), n], 1)             # [C, 6]
      residual = np.sum((p - q) * n, 1)
      weight = (geman_mcclure(residual, distance * ROBUST_SCALE) if robust
                else np.ones_like(residual))
      try:
        x = np.linalg.solve(jacobian.T @ (jacobian * weight[:, None]),
                            -jacobian.T @ (weight * residual))
      except np.linalg.LinAlgError:
        break
      t = _increment(x) @ t
  return t, fitness
