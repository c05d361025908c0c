"""Registration pairs from single real scans: a re-scan from a displaced virtual sensor
(or, for submaps accumulated along a drive, a second submap of the place).

No ground truth ships with the real clouds beside the project, and a pair made of a
cloud and a rigidly moved copy of it is too easy (the same points, the same
density). A re-scan differs the way two scans of a moving sensor differ:

  * the virtual sensor stands 2-10 m away (horizontally) and is turned by a yaw
    drawn over the whole circle;
  * it sees only what is visible from there (Open3D's hidden point removal, the
    spherical-flip operator of Katz et al. 2007) within its range;
  * both views are voxel-grid downsampled on grids with their own random offsets,
    so no point is shared, and get their own sensor noise.

Cloud 2 is expressed in the virtual sensor's frame; T_12 (the pose of the virtual
sensor in cloud 1's frame) maps it back, as `groundtruths.txt` expects.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np

from ssd_jax import geometry
from ssd_jax.data import clean, groundtruth, io


@dataclasses.dataclass(frozen=True)
class RescanConfig:
  """Distances in metres, angles in degrees."""
  min_shift: float = 2.0
  max_shift: float = 10.0
  max_range: float = 40.0     # both views keep what lies within this of their sensor
  voxel_size: float = 0.2     # 3DFeat-Net's KITTI processing
  noise_sigma: float = 0.02   # per-point Gaussian noise of each view
  hpr_radius_factor: float = 100.0   # HPR's flip radius, times the view's extent
  min_points: int = 2000      # a view with fewer points is redrawn
  # False for clouds accumulated along a drive (RobotCar's push-broom submaps): they have
  # no sensor at their origin and no sensor-centred occlusion, so the second view keeps
  # everything within max_range of its displaced centre, as a second submap of the place.
  occlusion: bool = True


def _voxel_grid(rng: np.random.Generator, points: np.ndarray, size: float) -> np.ndarray:
  """One point per occupied voxel (the centroid), on a grid shifted by a random offset."""
  offset = rng.uniform(0, size, 3)
  cells = np.floor((points + offset) / size).astype(np.int64)
  _, inverse, counts = np.unique(cells, axis=0, return_inverse=True, return_counts=True)
  sums = np.zeros((len(counts), 3))
  np.add.at(sums, inverse.reshape(-1), points)
  return sums / counts[:, None]


def visible_from(points: np.ndarray, viewpoint: np.ndarray, radius_factor: float) -> np.ndarray:
  """Indices of points [N, 3] visible from viewpoint [3] (hidden point removal)."""
  import open3d as o3d  # pylint: disable=g-import-not-at-top
  pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, np.float64)))
  extent = np.max(np.linalg.norm(points - viewpoint, axis=1))
  _, idx = pcd.hidden_point_removal(np.asarray(viewpoint, np.float64),
                                    radius_factor * max(extent, 1.0))
  return np.sort(np.asarray(idx, np.int64))


def _view(rng: np.random.Generator, points: np.ndarray, cfg: RescanConfig) -> np.ndarray:
  """points already in the view's sensor frame -> range crop, voxel grid, noise."""
  points = points[np.linalg.norm(points[:, :2], axis=1) <= cfg.max_range]
  points = _voxel_grid(rng, points, cfg.voxel_size)
  return points + rng.normal(0.0, cfg.noise_sigma, points.shape)


def rescan_pair(rng: np.random.Generator, points: np.ndarray, yaw_deg: float,
                cfg: RescanConfig = RescanConfig()) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
  """(cloud1 [N1, 3], cloud2 [N2, 3], T_12 [4, 4]) from one scan points [N, 3] metres
  centred on its sensor (or a submap centred on its origin, with cfg.occlusion False);
  the virtual sensor is turned by `yaw_deg` about z."""
  for _ in range(20):
    r = rng.uniform(cfg.min_shift, cfg.max_shift)
    a = rng.uniform(-np.pi, np.pi)
    shift = np.array([r * np.cos(a), r * np.sin(a), 0.0])
    seen = points[visible_from(points, shift, cfg.hpr_radius_factor)] if cfg.occlusion else points
    c, s = np.cos(np.deg2rad(yaw_deg)), np.sin(np.deg2rad(yaw_deg))
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    cloud2 = _view(rng, (seen - shift) @ rot, cfg)   # row form of R^T (p - c)
    if len(cloud2) >= cfg.min_points:
      break
  else:
    raise ValueError(f'no virtual sensor within {cfg.max_shift} m sees {cfg.min_points} points '
                     'of this scan')
  cloud1 = _view(rng, points, cfg)
  transform = np.eye(4)
  transform[:3, :3], transform[:3, 3] = rot, shift
  return cloud1, cloud2, transform


def make_rescan_set(sources: list, out: str | os.PathLike, seed: int = 0,
                    pairs_per_cloud: int = 8, cfg: RescanConfig = RescanConfig(),
                    progress=None) -> list[dict]:
  """Write a registration set of re-scan pairs (the sequence-folder layout that
  `benchmarks.read_registration_set` reads: OUT/groundtruths.txt, OUT/%06d.bin, and
  OUT/sources.tsv naming each pair's source scan and yaw).

  sources: cloud files (any format `io.read_cloud` reads). Each gives
  `pairs_per_cloud` pairs whose yaws fall one in each of that many equal bins of the
  circle, so every bin of relative yaw holds the same number of pairs. Pair n of
  cloud s draws from `default_rng((seed, s, n))`: the set is a function of the seed.
  -> one dict per pair (source, yaw_deg, points).
  """
  out = Path(out)
  out.mkdir(parents=True, exist_ok=True)
  rows, gts, n = [], [], 0
  width = 360.0 / pairs_per_cloud
  for s, source in enumerate(sources):
    points = clean.clean_cloud(io.read_cloud(source), str(source))
    for j in range(pairs_per_cloud):
      rng = np.random.default_rng((seed, s, j))
      yaw = -180.0 + width * (j + rng.uniform())
      cloud1, cloud2, transform = rescan_pair(rng, points, yaw, cfg)
      io.write_bin(out / f'{2 * n:06d}.bin', cloud1)
      io.write_bin(out / f'{2 * n + 1:06d}.bin', cloud2)
      gts.append(groundtruth.GroundTruthPair(2 * n, 2 * n + 1, transform))
      rows.append({'idx1': 2 * n, 'idx2': 2 * n + 1, 'source': Path(source).name,
                   'yaw_deg': float(geometry.yaw_deg(transform)), 'points': [len(cloud1), len(cloud2)]})
      n += 1
      if progress is not None:
        progress(1)
  groundtruth.write_groundtruths(out / 'groundtruths.txt', gts)
  lines = ['idx1\tidx2\tsource\tyaw_deg\tpoints1\tpoints2'] + [
      f'{r["idx1"]}\t{r["idx2"]}\t{r["source"]}\t{r["yaw_deg"]:.3f}\t{r["points"][0]}\t'
      f'{r["points"][1]}' for r in rows]
  (out / 'sources.tsv').write_text('\n'.join(lines) + '\n')
  return rows
