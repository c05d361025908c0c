"""Registration pairs from single real scans: a re-scan from a displaced virtual sensor
(or, for submaps accumulated along a drive, a second submap of the place).

A cloud and a rigidly moved copy of it is too easy a pair (the same points, the same
density). A re-scan differs the way two scans of a moving sensor differ:

  * the virtual sensor stands 2-10 m away (horizontally), turned by a yaw drawn over the
    whole circle, and sees only what is visible from there within its range (Open3D's
    hidden point removal, Katz et al. 2007);
  * optionally it is another unit (`sensor`, a name of `ssd_jax.sensors.SENSORS`): its
    view keeps only what that unit's beams would return (`sensors.resample`);
  * both views are voxel-grid downsampled on grids with their own random offsets, so no
    point is shared, and get their own sensor noise.

Cloud 2 is in the virtual sensor's frame; T_12 (its pose in cloud 1's frame) maps it
back, as `groundtruths.txt` expects.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np

from ssd_jax import geometry, sensors
from ssd_jax.data import clean, groundtruth, io, preprocess, registration_sets


BEAMS = ('select', 'cast')


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
  sensor: str = ''            # the virtual unit (ssd_jax.sensors); '' keeps every visible point
  # How the unit's beams make its view (BEAMS): 'select' keeps the scan's points that lie on
  # them (sensors.resample; the points stay on the scan's own rings), 'cast' casts its rays
  # at the scan's surfaces (sensors.cast; the returns lie on the unit's rings).
  beams: str = 'select'
  # True: the standpoint lies in the direction of a random point of the scan, not of a
  # uniform angle, so a scan that covers a sector only (KITTI's front-camera crops) is
  # re-scanned from over its own data when the standpoint is tens of metres away.
  toward_points: bool = False
  # Degrees (lo, hi): the virtual sensor is also tilted by an angle drawn from this range
  # about a random horizontal axis (a unit pitched or rolled: levelling's test sets).
  tilt: tuple[float, float] = (0.0, 0.0)

  def __post_init__(self):
    if self.beams not in BEAMS:
      raise ValueError(f'beams must be one of {BEAMS}, got {self.beams!r}')
    if self.beams == 'cast' and not self.sensor:
      raise ValueError("beams='cast' casts a unit's rays: name the unit (sensor)")


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


def _virtual_scan(rng: np.random.Generator, points: np.ndarray, yaw_deg: float,
                  cfg: RescanConfig) -> tuple[np.ndarray, np.ndarray]:
  """(what a virtual sensor min_shift-max_shift m away, turned by `yaw_deg` about z, sees
  of points [N, 3]: [M, 3] in its own frame; its pose T_12 [4, 4] in the points' frame)."""
  for _ in range(20):
    r = rng.uniform(cfg.min_shift, cfg.max_shift)
    if cfg.toward_points:
      p = points[rng.integers(len(points))]
      a = np.arctan2(p[1], p[0])
    else:
      a = rng.uniform(-np.pi, np.pi)
    shift = np.array([r * np.cos(a), r * np.sin(a), 0.0])
    seen = points[visible_from(points, shift, cfg.hpr_radius_factor)] if cfg.occlusion else points
    c, s = np.cos(np.deg2rad(yaw_deg)), np.sin(np.deg2rad(yaw_deg))
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    if cfg.tilt[1] > 0:   # drawn only then: the untilted sets keep their draws
      axis, half = rng.uniform(-np.pi, np.pi), np.deg2rad(rng.uniform(*cfg.tilt)) / 2.0
      rot = rot @ np.asarray(geometry.quaternion_to_matrix(np.array(
          [np.cos(half), np.sin(half) * np.cos(axis), np.sin(half) * np.sin(axis), 0.0])))
    local = (seen - shift) @ rot   # row form of R^T (p - c)
    if cfg.sensor and cfg.beams == 'cast':
      local = sensors.cast(local, sensors.get(cfg.sensor))
    elif cfg.sensor:
      local = local[sensors.resample(local, sensors.get(cfg.sensor))]
    cloud2 = _view(rng, local, cfg)
    if len(cloud2) >= cfg.min_points:
      transform = np.eye(4)
      transform[:3, :3], transform[:3, 3] = rot, shift
      return cloud2, transform
  raise ValueError(f'no virtual sensor within {cfg.max_shift} m sees {cfg.min_points} points '
                   'of this scan')


def rescan_pair(rng: np.random.Generator, points: np.ndarray, yaw_deg: float,
                cfg: RescanConfig = RescanConfig()) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
  """(cloud1 [N1, 3], cloud2 [N2, 3], T_12 [4, 4]) from one scan points [N, 3] metres
  centred on its sensor (or a submap centred on its origin, with cfg.occlusion False);
  the virtual sensor is turned by `yaw_deg` about z."""
  cloud2, transform = _virtual_scan(rng, points, yaw_deg, cfg)
  return _view(rng, points, cfg), cloud2, transform


def rescan_view(rng: np.random.Generator, points: np.ndarray,
                cfg: RescanConfig = RescanConfig()) -> np.ndarray:
  """What a virtual sensor (cfg: unit, distance) sees of one scan points [N, 3] metres,
  as float32 [M, 3] in the scan's own frame: the second view of a label-free training
  pair, which differs from the scan in standpoint, occlusion, beam pattern and sampling,
  not in pose (the objective draws the turn)."""
  cloud2, transform = _virtual_scan(rng, points, rng.uniform(-180.0, 180.0), cfg)
  return (cloud2 @ transform[:3, :3].T + transform[:3, 3]).astype(np.float32)


def _write_view(path: Path, cloud: np.ndarray) -> None:
  """With normals, as 3DFeat-Net's KITTI processing: N x 6 rows, whose layout the reader
  tells apart, where N x 3 float32 rows of an even N may also read as float64 ones."""
  io.write_bin(path, cloud, preprocess.estimate_normals(cloud))


def make_rescan_set(sources: list, out: str | os.PathLike, seed: int = 0,
                    pairs_per_cloud: int = 8, cfg: RescanConfig = RescanConfig(),
                    progress=None) -> list[dict]:
  """Write a registration set of re-scan pairs (the sequence-folder layout that
  `registration_sets.read_registration_set` reads: OUT/groundtruths.txt, OUT/%06d.bin (xyz +
  normals), and
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
      _write_view(out / f'{2 * n:06d}.bin', cloud1)
      _write_view(out / f'{2 * n + 1:06d}.bin', cloud2)
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


def make_cross_sensor_set(sources: list, out: str | os.PathLike, sensor_names, distance_bins,
                          pairs_per_cell: int = 1, seed: int = 0,
                          cfg: RescanConfig = RescanConfig(min_points=500, toward_points=True),
                          progress=None) -> list[dict]:
  """A cross-sensor registration set from real scans: for every source, unit of
  `sensor_names` and (low, high) metres of `distance_bins`, `pairs_per_cell` pairs of the
  scan (cloud 1) and its re-scan by that unit from a standpoint low-high metres away at a
  uniform yaw (cloud 2). Writes OUT/groundtruths.txt, OUT/%06d.bin (xyz + normals) and
  OUT/pairs.tsv
  (`registration_sets.write_pair_info`); pair n draws from `default_rng((seed, n))`.
  -> the pairs.tsv rows."""
  out = Path(out)
  out.mkdir(parents=True, exist_ok=True)
  rows, gts, n = [], [], 0
  for source in sources:
    points = clean.clean_cloud(io.read_cloud(source), str(source))
    name = Path(source).parent.name + '/' + Path(source).name
    for sensor in sensor_names:
      for lo, hi in distance_bins:
        for _ in range(pairs_per_cell):
          rng = np.random.default_rng((seed, n))
          pair_cfg = dataclasses.replace(cfg, sensor=sensor, min_shift=lo, max_shift=hi)
          # A unit with a limited field of view, turned away from a scan that covers a
          # sector only, sees nothing: such a yaw is drawn again.
          for attempt in range(10):
            try:
              cloud1, cloud2, transform = rescan_pair(rng, points, rng.uniform(-180, 180),
                                                      pair_cfg)
              break
            except ValueError:
              if attempt == 9:
                raise ValueError(f'{source}: no {sensor} standpoint {lo}-{hi} m away sees '
                                 f'{cfg.min_points} points of it') from None
          for k, cloud in enumerate((cloud1, cloud2)):
            _write_view(out / f'{2 * n + k:06d}.bin', cloud)
          gts.append(groundtruth.GroundTruthPair(2 * n, 2 * n + 1, transform))
          rows.append({'idx1': 2 * n, 'idx2': 2 * n + 1, 'sensor1': 'source', 'sensor2': sensor,
                       'distance_m': float(np.linalg.norm(transform[:2, 3])),
                       'yaw_deg': float(geometry.yaw_deg(transform)), 'source': name})
          n += 1
          if progress is not None:
            progress(1)
  groundtruth.write_groundtruths(out / 'groundtruths.txt', gts)
  registration_sets.write_pair_info(out, rows)
  return rows
