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


def plot_registration(points1: np.ndarray, points2: np.ndarray, kp1: np.ndarray,
                      kp2: np.ndarray, inliers: np.ndarray, path: str | os.PathLike,
                      title: str = '', max_points: int = 40_000, max_lines: int = 300,
                      seed: int = 0) -> None:
  """Both clouds from the top, side by side, with inlier matches as lines (paper Figs. 5-6).

  points1 [N1, 3], points2 [N2, 3] metres in their own frames; kp1 [M, 3], kp2 [M, 3]
  the matched keypoints; inliers [M] bool.
  """
  plt = _pyplot()
  rng = np.random.default_rng(seed)
  sub = lambda p: p[rng.choice(len(p), min(len(p), max_points), replace=False)]
  p1, p2 = sub(points1), sub(points2)
  shift = np.array([np.ptp(p1[:, 0]) * 0.5 + np.ptp(p2[:, 0]) * 0.5 + 10.0,
                    p1[:, 1].mean() - p2[:, 1].mean()]) + p1[:, :2].mean(0) - p2[:, :2].mean(0)
  fig, ax = plt.subplots(figsize=(14, 6))
  ax.scatter(p1[:, 0], p1[:, 1], s=0.2, c='tab:blue', linewidths=0)
  ax.scatter(p2[:, 0] + shift[0], p2[:, 1] + shift[1], s=0.2, c='tab:orange', linewidths=0)
  idx = np.flatnonzero(inliers)
  idx = idx[rng.permutation(len(idx))[:max_lines]]
  for i in idx:
    ax.plot([kp1[i, 0], kp2[i, 0] + shift[0]], [kp1[i, 1], kp2[i, 1] + shift[1]], '-',
            color='tab:green', lw=0.5, alpha=0.7)
  ax.set_aspect('equal')
  ax.set_xlabel('x (m)')
  ax.set_ylabel('y (m)')
  ax.set_title(title or f'{int(inliers.sum())} inlier matches of {len(inliers)}')
  fig.savefig(path, dpi=100, bbox_inches='tight')
  plt.close(fig)


def _finish_curve_plot(plt, fig, ax, path, xlim, xlabel, ylabel, title) -> None:
  """Percent y axis, grid, legend, save and close: shared by the curve figures."""
  ax.set_xlim(*xlim)
  ax.set_ylim(0, 100)
  ax.set_xlabel(xlabel)
  ax.set_ylabel(ylabel)
  ax.set_title(title)
  ax.grid(alpha=0.3)
  ax.legend(loc='lower right', fontsize=8)
  fig.savefig(path, dpi=120, bbox_inches='tight')
  plt.close(fig)


def plot_precision(thresholds: np.ndarray, curves: dict, path: str | os.PathLike,
                   title: str = 'Precision of nearest-neighbour matches', marker: float = 1.0) -> None:
  """Paper Fig. 4: fraction of matches within x metres of the ground truth.

  thresholds [T] metres; curves {label: [T] fractions}; `marker` draws the x line the
  paper reads the curves at.
  """
  plt = _pyplot()
  fig, ax = plt.subplots(figsize=(6.4, 4.8))
  for label, curve in curves.items():
    ax.plot(thresholds, 100 * np.asarray(curve), lw=1.6, label=label)
  ax.axvline(marker, color='k', ls='--', lw=0.8)
  ax.text(marker, 2, f' x = {marker:g} m', fontsize=8)
  _finish_curve_plot(plt, fig, ax, path, (0, float(np.max(thresholds))),
                     'distance to ground-truth location x (m)', 'precision (%)', title)


def plot_roc(curves: dict, path: str | os.PathLike, recall: float = 0.95,
             title: str = 'Descriptor matching ROC') -> None:
  """curves {label: (fpr [T], recall [T])}; a dashed line at the evaluated recall."""
  plt = _pyplot()
  fig, ax = plt.subplots(figsize=(5.6, 5.0))
  for label, (fpr, tpr) in curves.items():
    ax.plot(100 * np.asarray(fpr), 100 * np.asarray(tpr), lw=1.6, label=label)
  ax.plot([0, 100], [0, 100], color='0.6', lw=0.8, ls=':')
  ax.axhline(100 * recall, color='k', ls='--', lw=0.8)
  _finish_curve_plot(plt, fig, ax, path, (0, 100), 'false-positive rate (%)', 'recall (%)',
                     title)


def plot_keypoints(points: np.ndarray, keypoints: dict, path: str | os.PathLike,
                   view_radius: float = 40.0, max_points: int = 60_000, seed: int = 0) -> None:
  """Paper Fig. 3: each detector's keypoints as red dots on the same cloud, top view.

  points [N, 3] metres; keypoints {label: [K, 3] metres}, one panel each.
  """
  plt = _pyplot()
  rng = np.random.default_rng(seed)
  pts = points[np.linalg.norm(points[:, :2] - points[:, :2].mean(0), axis=1) < view_radius]
  if len(pts) > max_points:
    pts = pts[rng.choice(len(pts), max_points, replace=False)]
  fig, axes = plt.subplots(1, len(keypoints), figsize=(6.2 * len(keypoints), 6.2), squeeze=False)
  for ax, (label, kp) in zip(axes[0], keypoints.items()):
    ax.scatter(pts[:, 0], pts[:, 1], s=0.2, c='0.55', linewidths=0)
    ax.scatter(kp[:, 0], kp[:, 1], s=5, c='red', linewidths=0)
    ax.set_aspect('equal')
    ax.set_xlabel('x (m)')
    ax.set_ylabel('y (m)')
    ax.set_title(f'{label}: {len(kp)} keypoints')
  fig.savefig(path, dpi=110, bbox_inches='tight')
  plt.close(fig)


def plot_learning_curve(records: list[dict], path: str | os.PathLike,
                        title: str = 'Registration success during training') -> None:
  """One panel per test set: success (%) of each run's checkpoints against the training
  step (solid) and its precision at 1 m (dotted), baseline rows as horizontal lines.

  records: rows of `learning_curve.COLUMNS` (strings, as read back from the CSV).
  """
  plt = _pyplot()
  sets = list(dict.fromkeys(r['set'] for r in records))
  runs = list(dict.fromkeys(r['run'] for r in records if r['run']))
  fig, axes = plt.subplots(1, len(sets), figsize=(4.6 * len(sets), 4.0), squeeze=False)
  for ax, name in zip(axes[0], sets):
    for i, run in enumerate(runs):
      pts = sorted((int(r['step']), float(r['success']), float(r['precision_1m']))
                   for r in records if r['set'] == name and r['run'] == run)
      if pts:
        steps, success, prec = zip(*pts)
        ax.plot(steps, success, 'o-', color=f'C{i}', lw=1.6, label=f'{run}: success')
        ax.plot(steps, prec, 's:', color=f'C{i}', lw=1.0, label=f'{run}: precision @ 1 m')
    for i, r in enumerate(r for r in records if r['set'] == name and not r['run']):
      color = f'C{len(runs) + i}'
      ax.axhline(float(r['success']), color=color, ls='--', lw=1.2, label=f'{r["row"]}: success')
      ax.axhline(float(r['precision_1m']), color=color, ls=':', lw=1.0,
                 label=f'{r["row"]}: precision @ 1 m')
    ax.set_xscale('log')
    ax.set_ylim(0, 102)   # a baseline at 100 % stays visible
    ax.set_xlabel('training step')
    ax.set_ylabel('%')
    ax.set_title(name)
    ax.grid(alpha=0.3, which='both')
    ax.legend(loc='center right', fontsize=6)
  fig.suptitle(title)
  fig.savefig(path, dpi=120, bbox_inches='tight')
  plt.close(fig)


def plot_rotation_sweep(sweeps: dict, path: str | os.PathLike) -> None:
  """sweeps {checkpoint name: `orientation.rotation_sweep` output}: self-match rate and
  orientation error against the turn angle."""
  plt = _pyplot()
  fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
  for name, sweep in sweeps.items():
    angle = [r['angle_deg'] for r in sweep]
    ax1.plot(angle, [100 * r['self_match_rate'] for r in sweep], 'o-', label=name)
    ax2.plot(angle, [r['orientation_error_deg'] for r in sweep], 'o-', label=name)
  ax1.set(xlabel='turn about z (°)', ylabel='self-match rate (%)', ylim=(0, 100),
          title='turned cluster matches itself')
  ax2.set(xlabel='turn about z (°)', ylabel='median orientation error (°)', ylim=(0, 180),
          title='orientation follows the turn')
  for ax in (ax1, ax2):
    ax.set_xlim(0, 360)
    ax.set_xticks(range(0, 361, 45))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
  fig.savefig(path, dpi=120, bbox_inches='tight')
  plt.close(fig)


def plot_trajectory(poses: np.ndarray, path: str | os.PathLike, title: str = '',
                    failed: np.ndarray | None = None) -> None:
  """Top view of a trajectory: poses [S, 4, 4] of each scan in the first scan's frame
  (metres); `failed` [S - 1] bool marks the steps whose registration failed (red)."""
  plt = _pyplot()
  xy = poses[:, :2, 3]
  fig, ax = plt.subplots(figsize=(6.5, 6))
  ax.plot(xy[:, 0], xy[:, 1], '-', color='0.6', lw=1)
  ax.scatter(xy[:, 0], xy[:, 1], s=8, c=np.arange(len(xy)), cmap='viridis', zorder=3,
             label='scan positions (colour: index)')
  if failed is not None and np.any(failed):
    bad = np.flatnonzero(failed) + 1
    ax.scatter(xy[bad, 0], xy[bad, 1], s=30, facecolors='none', edgecolors='r', zorder=4,
               label='registration to the previous scan failed')
  ax.plot(xy[:1, 0], xy[:1, 1], 'k^', ms=8, label='first scan')
  ax.set_aspect('equal', adjustable='datalim')
  ax.set_xlabel('x (m)')
  ax.set_ylabel('y (m)')
  ax.set_title(title or f'{len(poses)} scans')
  ax.legend(loc='best', fontsize=8)
  fig.tight_layout()
  fig.savefig(path, dpi=120)
  plt.close(fig)
