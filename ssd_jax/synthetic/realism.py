"""Scan statistics for comparing synthetic scans with real ones, side by side.

The same functions run on both, so the comparison is apples to apples:
points per scan, range histogram, ground fraction and local-shape (PCA
eigenvalue) distributions in 1 m neighbourhoods for KITTI-style scans; point
spacing, neighbourhood sizes at the descriptor radii, local shape and the normals'
directions for Oxford-style test models.
"""

from __future__ import annotations

import glob
import os

import ml_collections
import numpy as np
from scipy import spatial

from ssd_jax.config_tools import upgrade
from ssd_jax.data import io
from ssd_jax.synthetic import dataset

COUNT_KEYS = ('scans', 'points per scan', 'models', 'points per model')
RANGE_BINS = (0.0, 5.0, 10.0, 20.0, 40.0, 80.0, np.inf)
# KITTI's object-benchmark scans keep what the front camera sees: azimuth within
# ±41° and elevation above about -15° (measured on the scans beside the project).
KITTI_FRONT_AZIMUTH_DEG = 41.0
KITTI_FRONT_MIN_ELEVATION_DEG = -15.2


def front_fov(points: np.ndarray) -> np.ndarray:
  """Points [N, 3] inside the front-camera crop of KITTI's object scans."""
  az = np.degrees(np.arctan2(points[:, 1], points[:, 0]))
  el = np.degrees(np.arctan2(points[:, 2], np.linalg.norm(points[:, :2], axis=1)))
  return points[(points[:, 0] > 0) & (np.abs(az) <= KITTI_FRONT_AZIMUTH_DEG) &
                (el >= KITTI_FRONT_MIN_ELEVATION_DEG)]


def range_histogram(points: np.ndarray) -> np.ndarray:
  """Fraction of points per horizontal-range bin `RANGE_BINS` (metres). -> [6]."""
  r = np.linalg.norm(points[:, :2], axis=1)
  return np.histogram(r, bins=RANGE_BINS)[0] / max(len(points), 1)


def ground_mask(points: np.ndarray, cell: float = 2.0, height: float = 0.25) -> np.ndarray:
  """Ground points: within `height` metres of the lowest point of their `cell`-metre
  xy cell, in cells whose lowest point is near the sensor's ground level (rejecting
  cells whose lowest point is a car roof or a wall). -> [N] bool."""
  ij = np.floor(points[:, :2] / cell).astype(np.int64)
  _, inv = np.unique(ij, axis=0, return_inverse=True)
  inv = inv.ravel()
  low = np.full(inv.max() + 1, np.inf)
  np.minimum.at(low, inv, points[:, 2])
  plausible = low < np.percentile(low, 10) + 1.5
  return (points[:, 2] - low[inv] < height) & plausible[inv]


def shape_features(points: np.ndarray, rng: np.random.Generator, num_samples: int = 2000,
                   radius: float = 1.0, min_neighbours: int = 5) -> dict[str, np.ndarray]:
  """PCA of the `radius`-metre neighbourhoods of random points.

  With eigenvalues l1 >= l2 >= l3: linearity (l1 - l2) / l1, planarity
  (l2 - l3) / l1, scattering l3 / l1. -> dict of [S] arrays.
  """
  tree = spatial.cKDTree(points)
  idx = rng.choice(len(points), min(num_samples, len(points)), replace=False)
  feats = []
  for nb in tree.query_ball_point(points[idx], radius):
    if len(nb) < min_neighbours:
      continue
    ev = np.linalg.eigvalsh(np.cov(points[nb].T))[::-1]
    l1 = max(ev[0], 1e-12)
    feats.append(((ev[0] - ev[1]) / l1, (ev[1] - ev[2]) / l1, ev[2] / l1))
  feats = np.array(feats).reshape(-1, 3)
  return {'linearity': feats[:, 0], 'planarity': feats[:, 1], 'scattering': feats[:, 2]}


def scan_statistics(scans: list[np.ndarray], seed: int = 0) -> dict[str, float]:
  """Averages over scans [N_i, 3]: point count, range histogram, ground fraction, and
  the shape-feature distributions (median, share planar > 0.5, share linear > 0.5)."""
  rng = np.random.default_rng(seed)
  counts, hists, ground, shape = [], [], [], {'linearity': [], 'planarity': [], 'scattering': []}
  for pts in scans:
    counts.append(len(pts))
    hists.append(range_histogram(pts))
    ground.append(ground_mask(pts).mean())
    for k, v in shape_features(pts, rng).items():
      shape[k].append(v)
  shape = {k: np.concatenate(v) for k, v in shape.items()}
  hist = np.mean(hists, axis=0)
  stats = {'scans': len(scans), 'points per scan': float(np.mean(counts)),
           'ground fraction': float(np.mean(ground))}
  for lo, hi, h in zip(RANGE_BINS[:-1], RANGE_BINS[1:], hist):
    stats[f'range {lo:g}-{hi:g} m' if np.isfinite(hi) else f'range > {lo:g} m'] = float(h)
  stats['planarity median'] = float(np.median(shape['planarity']))
  stats['share planar (> 0.5)'] = float(np.mean(shape['planarity'] > 0.5))
  stats['share linear (> 0.5)'] = float(np.mean(shape['linearity'] > 0.5))
  stats['scattering median'] = float(np.median(shape['scattering']))
  return stats


def compare_with_real(data: str, real: str, stride: int) -> tuple[str, dict]:
  """`scan_statistics` of every `stride`-th KITTI-style test scan of the synthetic set in
  `data` (raw, front-camera crop, and as written) beside the real KITTI scans under `real`
  (kitti_object_velodyne/ raw, example/kitti_* processed) -> (Markdown table, stats)."""
  config = ml_collections.ConfigDict(
      upgrade.upgrade_synthetic(dataset.read_manifest(data)['config']))
  raw, processed = [], []
  for seq in range(config.test_kitti.num_scenes):
    drive = dataset.make_drive(config, 'test_kitti', seq)
    for k in range(0, len(drive.poses), stride):
      raw.append(front_fov(drive.scan(k)))
      processed.append(io.read_cloud(os.path.join(data, 'test_kitti', f'{seq:02d}', f'{k:06d}.bin')))
  real_raw = [io.read_cloud(f) for f in sorted(glob.glob(f'{real}/kitti_object_velodyne/*.bin'))]
  real_proc = [io.read_cloud(f) for f in sorted(glob.glob(f'{real}/example/kitti_*.bin'))]
  cols = {'real KITTI raw (front crop)': real_raw, 'synthetic raw (front crop)': raw,
          'real KITTI processed (0.2 m voxels)': real_proc,
          'synthetic processed (0.2 m voxels)': processed}
  stats = {name: scan_statistics(scans) if scans else None for name, scans in cols.items()}
  return markdown_columns(stats), stats


# Ball radii of the descriptors (the learned model's 2 m and 4 m variants, FPFH's 4 m).
DESCRIPTOR_RADII = (2.0, 4.0)


def model_statistics(models: list[np.ndarray], seed: int = 0,
                     num_samples: int = 2000) -> dict[str, float]:
  """Averages over Oxford-style test models [N_i, 6] (xyz metres + unit normals) or
  [N_i, 3]: points, extent, nearest-neighbour spacing, points within the descriptor
  radii, local shape, and the share of normals that are near vertical (|n_z| > 0.9:
  ground, roofs) or near horizontal (|n_z| < 0.3: walls, poles)."""
  rng = np.random.default_rng(seed)
  rows = {k: [] for k in ('points per model', 'horizontal extent p95 (m)',
                          'height p5-p95 (m)', 'spacing median (m)',
                          *(f'points within {r:g} m (median)' for r in DESCRIPTOR_RADII),
                          'planarity median', 'share planar (> 0.5)', 'share linear (> 0.5)',
                          'normals with abs(n_z) > 0.9', 'normals with abs(n_z) < 0.3')}
  for model in models:
    xyz = np.asarray(model[:, :3], np.float64)
    tree = spatial.cKDTree(xyz)
    probe = xyz[rng.choice(len(xyz), min(num_samples, len(xyz)), replace=False)]
    rows['points per model'].append(len(xyz))
    rows['horizontal extent p95 (m)'].append(np.percentile(np.linalg.norm(xyz[:, :2], axis=1), 95))
    rows['height p5-p95 (m)'].append(float(np.subtract(*np.percentile(xyz[:, 2], [95, 5]))))
    rows['spacing median (m)'].append(np.median(tree.query(probe, k=2)[0][:, 1]))
    for r in DESCRIPTOR_RADII:
      rows[f'points within {r:g} m (median)'].append(
          np.median(tree.query_ball_point(probe, r, return_length=True)))
    shape = shape_features(xyz, rng, num_samples)
    rows['planarity median'].append(np.median(shape['planarity']))
    rows['share planar (> 0.5)'].append(np.mean(shape['planarity'] > 0.5))
    rows['share linear (> 0.5)'].append(np.mean(shape['linearity'] > 0.5))
    nz = np.abs(model[:, 5]) if model.shape[1] >= 6 else None
    rows['normals with abs(n_z) > 0.9'].append(np.nan if nz is None else np.mean(nz > 0.9))
    rows['normals with abs(n_z) < 0.3'].append(np.nan if nz is None else np.mean(nz < 0.3))
  return {'models': len(models), **{k: float(np.mean(v)) for k, v in rows.items()}}


def markdown_columns(stats: dict[str, dict | None]) -> str:
  """Statistics of several sources side by side: {column: stats or None} -> Markdown."""
  keys = next(s for s in stats.values() if s)
  lines = ['| statistic | ' + ' | '.join(stats) + ' |', '|---' * (len(stats) + 1) + '|']
  for key in keys:
    cells = ['n/a' if s is None else (f'{s[key]:,.0f}' if key in COUNT_KEYS else f'{s[key]:.3f}')
             for s in stats.values()]
    lines.append(f'| {key} | ' + ' | '.join(cells) + ' |')
  return '\n'.join(lines)


def compare_oxford_with_real(data: str, real: str, stride: int = 1) -> tuple[str, dict]:
  """`model_statistics` of every `stride`-th Oxford-style test model of the synthetic set
  in `data` beside the real RobotCar test models under `real` (example/oxford_*.bin)
  -> (Markdown table, stats). Each real model also gets its own column, so the table
  shows the spread between real models."""
  synthetic = [io.read_bin_rows(f, 'xyzn') for f in sorted(
      glob.glob(os.path.join(data, 'test_oxford', 'test_models', '*.bin')),
      key=lambda f: int(os.path.splitext(os.path.basename(f))[0]))[::stride]]
  real_files = sorted(glob.glob(f'{real}/example/oxford_*.bin'))
  stats = {f'real {os.path.basename(f)}': model_statistics([io.read_bin_rows(f, 'xyzn')])
           for f in real_files}
  stats['synthetic (mean over models)'] = model_statistics(synthetic) if synthetic else None
  if not any(stats.values()):
    raise FileNotFoundError(f'no Oxford-style models under {data}/test_oxford/test_models '
                            f'or {real}/example')
  return markdown_columns(stats), stats
