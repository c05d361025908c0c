"""RANSAC for rigid registration from putative correspondences (REFERENCE §6).

`ransac_sequential` is the reference rule (P. Kovesi's MATLAB `ransac.m`, as
3DFeat-Net evaluates): one minimal sample of 3 correspondences per trial, a
Kabsch fit, inliers within 1 m, and the adaptive trial count
N = log(1 - p) / log(1 - w^3), updated after every trial that ties or beats the
best inlier count, at least `min_trials`; it stops when trials >= N or trials >
max_trials. The best hypothesis is refit on all its inliers.
"""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class RansacResult:
  transform: np.ndarray   # [4, 4] T_12: maps cloud 2 into cloud 1's frame
  inliers: np.ndarray     # [C] bool over the correspondences
  trials: int


def kabsch(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
  """Least-squares rigid T [4, 4] with T src ≈ dst; src, dst [n, 3], n >= 3."""
  mu_s, mu_d = src.mean(0), dst.mean(0)
  u, _, vt = np.linalg.svd((src - mu_s).T @ (dst - mu_d))
  d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
  rot = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
  t = np.eye(4)
  t[:3, :3], t[:3, 3] = rot, mu_d - rot @ mu_s
  return t


def _degenerate(p: np.ndarray, eps: float = 1e-6) -> bool:
  """Three (nearly) collinear or coincident points fix no rotation."""
  return np.linalg.norm(np.cross(p[1] - p[0], p[2] - p[0])) < eps


def ransac_sequential(xyz1: np.ndarray, xyz2: np.ndarray, rng: np.random.Generator,
                      inlier_threshold: float = 1.0, confidence: float = 0.99,
                      max_trials: int = 10_000, min_trials: int = 10,
                      max_data_trials: int = 100) -> RansacResult:
  """Correspondences xyz1[i] <-> xyz2[i] ([C, 3] metres each) -> T_12 by RANSAC."""
  n = len(xyz1)
  if n < 3:
    raise ValueError(f'RANSAC needs at least 3 correspondences, got {n}')
  best_score, best_inliers, trials, needed = -1, None, 0, float(min_trials)
  while needed > trials:
    for _ in range(max_data_trials):
      sample = rng.choice(n, 3, replace=False)
      if not _degenerate(xyz2[sample]):
        break
    model = kabsch(xyz2[sample], xyz1[sample])
    residual = np.linalg.norm(xyz2 @ model[:3, :3].T + model[:3, 3] - xyz1, axis=1)
    inliers = residual < inlier_threshold
    score = int(inliers.sum())
    if score >= best_score:
      best_score, best_inliers = score, inliers
      w = score / n
      p_no_outliers = min(max(1.0 - w ** 3, np.finfo(float).eps), 1.0 - np.finfo(float).eps)
      needed = max(float(min_trials), np.log(1.0 - confidence) / np.log(p_no_outliers))
    trials += 1
    if trials > max_trials:
      break
  if best_score >= 3:
    transform = kabsch(xyz2[best_inliers], xyz1[best_inliers])
  else:
    transform = np.eye(4)
  return RansacResult(transform, best_inliers, trials)
