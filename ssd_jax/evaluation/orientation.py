"""Does a detector's z-orientation turn with the cloud? (3DFeat-Net's rotation invariance.)

The descriptor sees each cluster rotated by minus its predicted orientation, so it is
invariant to a turn of the cloud by phi only if the orientation turns by phi too. For
clusters at the same points of a cloud and of its copy turned by phi, the error is
|theta_turned - theta - phi| wrapped to [0, 180] degrees: 0 for a perfectly equivariant
detector, |phi| for one whose orientation ignores the turn, and uniform on [0, 180]
(median 90) for one whose orientation is unrelated to the cluster.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ssd_jax import geometry, inference


def orientation_error_deg(theta: np.ndarray, theta_turned: np.ndarray,
                          phi: float) -> np.ndarray:
  """Orientations [K] radians before and after a turn by phi radians -> errors [K] degrees."""
  diff = np.asarray(theta_turned, np.float64) - np.asarray(theta, np.float64) - phi
  return np.abs(np.degrees(np.angle(np.exp(1j * diff))))


def orientation_errors(model: inference.Model, points: np.ndarray, centers: np.ndarray,
                       angles: Sequence[float]) -> np.ndarray:
  """points [N, 3], centers [K, 3] metres, angles [A] radians -> errors [A, K] degrees."""
  _, theta = inference.detect_at(model, points, centers)
  out = []
  for phi in angles:
    rz = np.asarray(geometry.rotation_z(np.float32(phi)), np.float32)
    _, turned = inference.detect_at(model, points @ rz.T, centers @ rz.T)
    out.append(orientation_error_deg(theta, turned, phi))
  return np.stack(out)


def summarize(errors: np.ndarray, within_deg: float = 15.0) -> dict[str, float]:
  """-> {'median_deg', 'within'}: the median error and the share below `within_deg`
  (0.083 for errors uniform on [0, 180] degrees)."""
  return {'median_deg': float(np.median(errors)), 'within': float(np.mean(errors < within_deg))}
