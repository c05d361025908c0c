"""Figures (matplotlib, headless)."""

from __future__ import annotations

import os

import numpy as np


def _pyplot():
  import matplotlib  # pylint: disable=g-import-not-at-top
  matplotlib.use('Agg')
  import matplotlib.pyplot as plt  # pylint: disable=g-import-not-at-top
  return plt


def plot_scan(points: np.ndarray, path: str | os.PathLike, title: str = '',
              view_radius: float = 45.0, max_points: int = 60_000, seed: int = 0) -> None:
  """Top view and perspective view of a scan [N, 3] metres, coloured by height."""
  plt = _pyplot()
  rng = np.random.default_rng(seed)
  pts = points[np.linalg.norm(points[:, :2], axis=1) < view_radius]
  if len(pts) > max_points:
    pts = pts[rng.choice(len(pts), max_points, replace=False)]
  z = pts[:, 2]
  lo, hi = np.percentile(z, [1, 99])
  fig = plt.figure(figsize=(13, 5.6))
  ax = fig.add_subplot(1, 2, 1)
  order = np.argsort(z)
  ax.scatter(pts[order, 0], pts[order, 1], c=z[order], s=0.3, cmap='viridis', vmin=lo, vmax=hi,
             linewidths=0)
  ax.plot([0], [0], 'r^', ms=8, label='sensor')
  ax.set_aspect('equal')
  ax.set_xlim(-view_radius, view_radius)
  ax.set_ylim(-view_radius, view_radius)
  ax.set_xlabel('x (m, forward)')
  ax.set_ylabel('y (m, left)')
  ax.set_title('top view')
  ax.legend(loc='upper right', fontsize=8)
  ax3 = fig.add_subplot(1, 2, 2, projection='3d')
  near = np.linalg.norm(pts[:, :2], axis=1) < 0.6 * view_radius
  sc = ax3.scatter(pts[near, 0], pts[near, 1], z[near], c=z[near], s=0.4, cmap='viridis',
                   vmin=lo, vmax=hi, linewidths=0, depthshade=False)
  ax3.view_init(elev=30, azim=-125)
  ax3.set_xlim(-0.6 * view_radius, 0.6 * view_radius)
  ax3.set_ylim(-0.6 * view_radius, 0.6 * view_radius)
  ax3.set_zlim(lo - 1, lo - 1 + 0.3 * view_radius)
  ax3.set_box_aspect((1, 1, 0.25), zoom=1.3)
  ax3.set_title('perspective')
  ax3.set_axis_off()
  fig.colorbar(sc, ax=[ax, ax3], shrink=0.8, label='height z (m)')
  if title:
    fig.suptitle(title)
  fig.savefig(path, dpi=110, bbox_inches='tight')
  plt.close(fig)
