"""Registration errors of one pair: RTE, RRE and success (docs/method.md §4)."""

from __future__ import annotations

import numpy as np

from ssd_jax import geometry

MAX_RTE = 2.0   # metres
MAX_RRE = 5.0   # degrees


def registration_errors(t_gt: np.ndarray, t_est: np.ndarray) -> dict[str, float]:
  """RTE (m), RRE as the paper computes it (sum of |ZYX Euler angles| of R_gt^T R_est,
  degrees), the geodesic RRE (degrees) and success (RTE < 2 m and RRE < 5°)."""
  t_gt, t_est = np.asarray(t_gt, np.float64), np.asarray(t_est, np.float64)
  rte = float(geometry.translation_error(t_gt[:3, 3], t_est[:3, 3]))
  rre = float(geometry.euler_sum_rre_deg(t_gt[:3, :3], t_est[:3, :3]))
  geo = float(geometry.geodesic_angle_deg(t_gt[:3, :3], t_est[:3, :3]))
  return {'rte': rte, 'rre': rre, 'rre_geodesic': geo,
          'success': bool(rte < MAX_RTE and rre < MAX_RRE)}
