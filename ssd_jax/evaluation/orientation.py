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


def rotation_sweep(model: inference.Model, points: np.ndarray, centers: np.ndarray,
                   angles_deg: Sequence[float]) -> list[dict[str, float]]:
  """Turn the whole cloud about z by each angle and compare every cluster with itself.

  points [N, 3], centers [K, 3] metres. The turned cloud keeps its point order, so
  each ball holds the same points: what changes is only what the network does with a
  turned cluster. Per angle: the median orientation error (degrees; 0 = the head turns
  with the cluster), the median descriptor distance between a cluster and its turned
  self, and the self-match rate: the share of turned clusters whose nearest descriptor
  among the unturned ones is their own (1 = matching survives the turn).
  """
  base = inference.describe(model, points, centers)
  _, theta = inference.detect_at(model, points, centers)
  out = []
  for deg in angles_deg:
    phi = np.deg2rad(deg)
    rz = np.asarray(geometry.rotation_z(np.float32(phi)), np.float32)
    turned_pts, turned_ctr = points @ rz.T, centers @ rz.T
    desc = inference.describe(model, turned_pts, turned_ctr)
    _, turned = inference.detect_at(model, turned_pts, turned_ctr)
    d2 = np.sum((desc[:, None, :] - base[None, :, :]) ** 2, -1)
    out.append({'angle_deg': float(deg),
                'orientation_error_deg': float(np.median(orientation_error_deg(theta, turned, phi))),
                'descriptor_distance': float(np.median(np.sqrt(np.diag(d2)))),
                'self_match_rate': float(np.mean(np.argmin(d2, 1) == np.arange(len(centers))))})
  return out
