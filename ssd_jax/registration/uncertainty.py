"""How well a registered pose is fixed: the information matrix a pose graph takes, and the
directions the two scans leave free (distinct poses that fit as well are the verdict's
'ambiguous candidates', `verdict.assess`).

Two scans of a straight corridor, a tunnel or a road between barriers see walls whose
normals are all across the way: a shift along it leaves every point-to-plane residual
unchanged, so RANSAC and ICP return whichever shift they start from, with a perfect
fitness. The point-to-plane Hessian at the final pose shows it (Gelfand et al., 3DIM 2003;
Zhang et al., ICRA 2016): sum over correspondences of J^T J, J = [(q - c) x n, n] (q a
cloud-1 point, n its normal, c their centroid; rotation scaled by their RMS distance from
c so both parts are in metres), divided by their count. Its Schur complement of the
rotation block is the translation's constraint: a direction whose eigenvalue there is
under `MIN_CONSTRAINT` is a shift no surface resists. `information_matrix` is Open3D's
`get_information_matrix_from_point_clouds` ((rx, ry, rz, tx, ty, tz), target points), what
Open3D's pose-graph optimisation takes for an edge.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ssd_jax.registration import icp

# Metres: correspondences within this distance at the final pose (the verification's last
# ICP distance).
DISTANCE = 0.5
# Per-correspondence eigenvalue of the translation's constraint (above) under which its
# direction counts as free. Two scans of a straight corridor, a tunnel and a highway
# between barriers leave 0.0027, 0.0017 and 0.0006 along them (the walls' noise); the
# pairs of the project's sets that register, real and synthetic, no less than 0.016
# (docs/registration.md: degenerate scenes). The bound sits between, 2-3 times from each.
MIN_CONSTRAINT = 0.0075
# Fewer correspondences than this at the final pose: the pose is fixed by almost nothing.
MIN_CORRESPONDENCES = 30


@dataclasses.dataclass(frozen=True)
class PoseUncertainty:
  """What the scans fix of a pose T_12.

  information: [6, 6] Open3D's information matrix (`information_matrix`).
  eigenvalues: [6] ascending, of the scaled point-to-plane Hessian per correspondence.
  directions: [6, 6] its unit eigenvectors as rows, (rx, ry, rz, tx, ty, tz): rotation in
    radians times `scale`, translation in metres.
  translation_constraint: [3] ascending, the translation's constraint (the Hessian's
    Schur complement of its rotation block) per correspondence.
  translation_directions: [3, 3] its unit eigenvectors as rows (x, y, z).
  scale: metres, the RMS distance of the correspondences from their centroid.
  correspondences: cloud-2 points with a cloud-1 point within DISTANCE at the pose.
  """
  information: np.ndarray
  eigenvalues: np.ndarray
  directions: np.ndarray
  translation_constraint: np.ndarray
  translation_directions: np.ndarray
  scale: float
  correspondences: int

  @property
  def free(self) -> str:
    """'' when the scans fix the pose, else one line naming what they leave free."""
    return self.free_under(MIN_CONSTRAINT)

  def free_under(self, bound: float) -> str:
    """`free` with `bound` in place of MIN_CONSTRAINT: '' when every shift is held by at
    least `bound` per correspondence, else one line naming the least held."""
    if self.correspondences < MIN_CORRESPONDENCES:
      return (f'only {self.correspondences} points of cloud 2 lie within {DISTANCE:g} m of '
              'cloud 1 at the pose: the scans barely overlap there')
    if self.translation_constraint[0] < bound:
      return (f'{describe_direction(np.append(np.zeros(3), self.translation_directions[0]))}'
              f' is not fixed by the scans ({self.translation_constraint[0]:.2g} per '
              f'correspondence, under {bound:g}: a corridor, tunnel or road between barriers?)')
    return ''

  def to_json(self) -> dict:
    return {'free': self.free, 'information_matrix': self.information.tolist(),
            'smallest_eigenvalue': float(self.eigenvalues[0]),
            'smallest_direction': self.directions[0].tolist(),
            'eigenvalues': self.eigenvalues.tolist(),
            'translation_constraint': self.translation_constraint.tolist(),
            'least_fixed_translation': self.translation_directions[0].tolist(),
            'scale_m': self.scale,
            'correspondences': self.correspondences}


def describe_direction(direction: np.ndarray) -> str:
  """A unit 6-vector (rx, ry, rz, tx, ty, tz) -> 'translation along (0.99, 0.02, 0.00)' or
  'rotation about (0.00, 0.00, 1.00)', whichever part is larger."""
  rotation, translation = direction[:3], direction[3:]
  kind, axis = (('translation along', translation)
                if np.linalg.norm(translation) >= np.linalg.norm(rotation)
                else ('rotation about', rotation))
  axis = axis / np.linalg.norm(axis)
  axis = axis * np.sign(axis[np.argmax(np.abs(axis))])   # the largest component positive
  axis = np.round(axis, 2) + 0.0                          # no '-0.00'
  return f'{kind} ({axis[0]:.2f}, {axis[1]:.2f}, {axis[2]:.2f})'


def assess(target: icp.Surface, source: np.ndarray, transform: np.ndarray,
           origin: np.ndarray | None = None, distance: float = DISTANCE) -> PoseUncertainty:
  """What cloud 1 (`target`) and cloud 2's points source [M, 3] metres fix of the pose T_12
  [4, 4], from their correspondences within `distance` at it: Open3D's information
  matrix (about `origin` [3], cloud 1's frame origin in these coordinates, default 0) and
  the scaled point-to-plane Hessian's eigen-decomposition."""
  moved = np.asarray(source, np.float64) @ transform[:3, :3].T + transform[:3, 3]
  found, idx, _ = icp.correspondences(target, moved, distance)
  idx = idx[found]
  q = target.points[idx]
  information = information_matrix(q if origin is None else q - origin)
  if len(idx) < MIN_CORRESPONDENCES:
    return PoseUncertainty(information, np.zeros(6), np.eye(6), np.zeros(3), np.eye(3), 0.0,
                           len(idx))
  n = target.normals_at(idx)
  r = q - q.mean(0)
  scale = float(np.sqrt(np.mean(np.sum(r * r, 1)))) or 1.0
  jacobian = np.concatenate([np.cross(r, n) / scale, n], 1)          # [C, 6]
  hessian = jacobian.T @ jacobian / len(idx)
  values, vectors = np.linalg.eigh(hessian)
  # Translation after the best rotation: H_tt - H_tr H_rr^-1 H_rt (pinv: a rotation no
  # surface resists either leaves the translation as it is).
  schur = hessian[3:, 3:] - hessian[3:, :3] @ np.linalg.pinv(hessian[:3, :3]) @ hessian[:3, 3:]
  t_values, t_vectors = np.linalg.eigh((schur + schur.T) / 2)
  return PoseUncertainty(information, values, vectors.T, t_values, t_vectors.T, scale,
                         len(idx))


def information_matrix(partners: np.ndarray) -> np.ndarray:
  """The cloud-1 points [C, 3] metres of the correspondences at a pose -> [6, 6] Open3D's
  `get_information_matrix_from_point_clouds` ((rx, ry, rz, tx, ty, tz) order): the sum of
  G^T G with G = [[q]_x^T | I] over them, the edge information of Open3D's pose graph."""
  g = np.zeros((len(partners), 3, 6))
  x, y, z = partners[:, 0], partners[:, 1], partners[:, 2]
  g[:, 0, 1], g[:, 0, 2] = z, -y
  g[:, 1, 0], g[:, 1, 2] = -z, x
  g[:, 2, 0], g[:, 2, 1] = y, -x
  g[:, :, 3:] = np.eye(3)
  return np.einsum('cki,ckj->ij', g, g)
