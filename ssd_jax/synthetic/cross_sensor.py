"""A cross-sensor test set: one place scanned by two different LiDARs standing 5-40 m
apart, at any relative yaw, with the exact T_12.

    OUT/groundtruths.txt   3DFeat-Net's format, pairs (2n, 2n + 1)
    OUT/%06d.bin           N x 6 (xyz + normals), 0.2 m voxel grid, each in its sensor's frame
    OUT/pairs.tsv          idx1 idx2 sensor1 sensor2 distance_m yaw_deg source
    OUT/cross_sensor.json  the config and seed that made it

Cloud 1 of every pair comes from the reference unit (`cross_sensor.reference`, a
KITTI-like HDL-64E); cloud 2 from each unit of `cross_sensor.sensors` in turn
(`ssd_jax.sensors`), standing at a pose of the same drive whose distance from cloud 1's
falls in each bin of `cross_sensor.distance_bins`, turned about its z axis by a uniform
yaw. The scenes are their own (split seed 5), unseen by any training split. Pair n draws
from (seed, 5, scene, n): the set is a function of the config.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
import shutil
from typing import Callable, Sequence

import numpy as np

from ssd_jax import geometry, sensors
from ssd_jax.data import groundtruth, io, kitti, registration_sets
from ssd_jax.synthetic import dataset, lidar, scene as scene_lib, trajectory

SPLIT = 5
MANIFEST = 'cross_sensor.json'
# The config sections this set is a function of.
SETTINGS = ('seed', 'scene_length', 'voxel_size', 'normal_radius', 'scene', 'lidar',
            'cross_sensor')


def check_config(config) -> None:
  """Refuse a cross-sensor section that names unknown sensors or empty distance bins."""
  cfg = config.cross_sensor
  for name in (cfg.reference, *cfg.sensors):
    try:
      sensors.get(name)
    except ValueError as e:
      raise dataset.SyntheticConfigError(f'cross_sensor: {e}') from None
  for lo, hi in cfg.distance_bins:
    if not 0 <= lo < hi:
      raise dataset.SyntheticConfigError(
          f'cross_sensor.distance_bins: each bin must be (low, high) metres with 0 <= low < '
          f'high, got ({lo}, {hi})')
    if hi > config.scene_length - 2 * trajectory.MARGIN:
      raise dataset.SyntheticConfigError(
          f'cross_sensor.distance_bins: {hi} m is longer than a drive of scene_length '
          f'{config.scene_length} m (less {2 * trajectory.MARGIN:.0f} m of margins)')
  tilt = tuple(cfg.get('tilt', (0.0, 0.0)))
  if len(tilt) != 2 or not 0 <= tilt[0] <= tilt[1] <= 90:
    raise dataset.SyntheticConfigError(
        f'cross_sensor.tilt must be (low, high) degrees with 0 <= low <= high <= 90, got {tilt}')
  if cfg.num_scenes < 1 or cfg.pairs_per_cell < 1:
    raise dataset.SyntheticConfigError('cross_sensor.num_scenes and pairs_per_cell must be >= 1')


def _sensor_model(config, name: str) -> lidar.LidarModel:
  """The unit `name` with the config's noise, dropout and mount height."""
  noise = {k: v for k, v in dict(config.lidar).items()
           if k not in ('upper_beams', 'upper_elevation', 'lower_beams', 'lower_elevation',
                        'azimuth_step', 'max_range', 'horizontal_fov')}
  return lidar.LidarModel.for_sensor(name, **noise)


def _pose_at_distance(rng, positions: np.ndarray, i: int, lo: float, hi: float) -> int | None:
  """A random pose index whose horizontal distance from pose i is in [lo, hi)."""
  d = np.linalg.norm(positions[:, :2] - positions[i, :2], axis=1)
  candidates = np.flatnonzero((d >= lo) & (d < hi))
  return int(rng.choice(candidates)) if len(candidates) else None


def _tilt(rng: np.random.Generator, lo: float, hi: float) -> np.ndarray:
  """[3, 3]: a turn by an angle drawn in [lo, hi] degrees about a random horizontal axis
  (a unit mounted pitched or rolled, a robot on a slope)."""
  angle, heading = np.radians(rng.uniform(lo, hi)), rng.uniform(-np.pi, np.pi)
  axis = np.array([np.cos(heading), np.sin(heading), 0.0])
  k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
  return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def count_pairs(config) -> int:
  cfg = config.cross_sensor
  return cfg.num_scenes * len(cfg.sensors) * len(cfg.distance_bins) * cfg.pairs_per_cell


def generate(config, out: str | os.PathLike, progress: Callable[[int], None] | None = None,
             overwrite: bool = False) -> dict:
  """Write the set to `out` atomically; reuse it when it was made from the same config.
  `progress(1)` after each pair. -> the manifest."""
  dataset.check_config(config)
  check_config(config)
  # Other sections (the real re-scan settings of the same config) do not change this set.
  out = Path(out)
  settings = {k: v for k, v in json.loads(config.to_json()).items() if k in SETTINGS}
  manifest_path = out / MANIFEST
  if manifest_path.is_file():
    existing = json.loads(manifest_path.read_text())
    if existing['config'] == settings:
      return {**existing, 'reused': True}
    if not overwrite:
      raise dataset.SyntheticConfigError(f'{out} holds a cross-sensor set made with a different '
                                         'config; pass --overwrite or choose another --out')
  elif out.exists() and any(out.iterdir()):
    raise dataset.SyntheticConfigError(f'{out} exists and is not a cross-sensor set; choose '
                                       'another --out')
  partial = out.with_name(out.name + '.partial')
  if partial.exists():
    shutil.rmtree(partial)
  partial.mkdir(parents=True)
  cfg = config.cross_sensor
  models = {name: _sensor_model(config, name) for name in (cfg.reference, *cfg.sensors)}
  tilt = tuple(cfg.get('tilt', (0.0, 0.0)))
  gts, rows, n = [], [], 0
  for scene_idx in range(cfg.num_scenes):
    seed = (int(config.seed), SPLIT, scene_idx)
    rng = np.random.default_rng(seed)
    scene = scene_lib.make_scene(rng, config.scene_length, config.scene.clutter_scale,
                                 config.scene.varied_objects)
    poses = trajectory.drive(scene, rng, 1.0, config.lidar.mount_height)
    raycaster = lidar.Raycaster(scene)
    # One physical unit of each kind per scene: its calibration error is fixed.
    calibration = {name: m.calibration(np.random.default_rng((*seed, k)))
                   for k, (name, m) in enumerate(models.items())}
    for sensor in cfg.sensors:
      for lo, hi in cfg.distance_bins:
        for _ in range(cfg.pairs_per_cell):
          pair_rng = np.random.default_rng((*seed, 1 << 20, n))
          for _ in range(100):
            i = int(pair_rng.integers(len(poses)))
            j = _pose_at_distance(pair_rng, poses[:, :3, 3], i, lo, hi)
            if j is not None:
              break
          else:
            raise dataset.SyntheticConfigError(
                f'cross_sensor: scene {scene_idx} has no two poses {lo}-{hi} m apart')
          yaw = pair_rng.uniform(-180.0, 180.0)
          pose2 = poses[j] @ geometry.make_transform(geometry.rotation_z(np.radians(yaw)),
                                                     np.zeros(3))
          if tilt[1] > 0:   # drawn only then: an upright set keeps its draws
            pose2 = pose2 @ geometry.make_transform(_tilt(pair_rng, *tilt), np.zeros(3))
          clouds = []
          for name, pose in ((cfg.reference, poses[i]), (sensor, pose2)):
            raw, _ = lidar.scan(raycaster, pose, models[name], pair_rng, calibration[name])
            clouds.append(dataset.process(config, raw))
          for k, (points, normals) in enumerate(clouds):
            io.write_bin(partial / f'{2 * n + k:06d}.bin', points, normals)
          transform = np.linalg.inv(poses[i]) @ pose2
          gts.append(groundtruth.GroundTruthPair(2 * n, 2 * n + 1, transform))
          rows.append({'idx1': 2 * n, 'idx2': 2 * n + 1, 'sensor1': cfg.reference,
                       'sensor2': sensor,
                       # The distance the pose was drawn at: on the ground, in the world.
                       'distance_m': float(np.linalg.norm(poses[j, :2, 3] - poses[i, :2, 3])),
                       'yaw_deg': float(geometry.yaw_deg(transform)),
                       'source': f'scene{scene_idx}'})
          n += 1
          if progress is not None:
            progress(1)
  groundtruth.write_groundtruths(partial / 'groundtruths.txt', gts)
  registration_sets.write_pair_info(partial, rows)
  manifest = {'config': settings, 'pairs': n}
  (partial / MANIFEST).write_text(json.dumps(manifest, indent=2, sort_keys=True) + '\n')
  if out.exists():
    shutil.rmtree(out)
  os.replace(partial, out)
  return {**manifest, 'reused': False}


SCANS_SPLIT = 6   # scenes of `write_sensor_scans`: neither a training nor a test split's


def write_sensor_scans(config, sensor: str | Sequence[str], out: str | os.PathLike,
                       num_scenes: int = 3, spacing: float = 6.0,
                       progress: Callable[[int], None] | None = None,
                       poses_out: str | os.PathLike | None = None) -> int:
  """Unlabeled scans of one unit (`ssd_jax.sensors`), or of several in turn (scan k of a
  drive by unit k mod their number: a mixed-sensor drive), along drives through
  `num_scenes` scenes of their own (split 6), a scan every `spacing` metres, in capture order:
  OUT/<scene>_<k>.bin (xyz + normals, 0.2 m voxel grid, the sensor's frame) and no poses,
  as a user's folder of scans would be. `poses_out`: a file outside OUT to write their
  ground-truth poses T_world_sensor to (KITTI's layout, one row-major 3 x 4 per scan in
  the folder's sorted order; scene s's world shifted SCENE_APART * s metres along x, so
  that no pose relates two scenes), for measuring what is mined from them
  (`registration.mining.label_errors`). -> the number of scans."""
  dataset.check_config(config)
  units = [sensor] if isinstance(sensor, str) else list(sensor)
  models = [_sensor_model(config, name) for name in units]
  out = Path(out)
  out.mkdir(parents=True, exist_ok=True)
  count, all_poses = 0, []
  for scene_idx in range(num_scenes):
    seed = (int(config.seed), SCANS_SPLIT, scene_idx)
    rng = np.random.default_rng(seed)
    scene = scene_lib.make_scene(rng, config.scene_length, config.scene.clutter_scale,
                                 config.scene.varied_objects)
    poses = trajectory.drive(scene, rng, spacing, config.lidar.mount_height)
    apart = poses.copy()
    apart[:, 0, 3] += SCENE_APART * scene_idx
    all_poses.append(apart)
    raycaster = lidar.Raycaster(scene)
    calibrations = [m.calibration(np.random.default_rng((*seed, 0))) for m in models]
    for k, pose in enumerate(poses):
      unit = k % len(models)
      raw, _ = lidar.scan(raycaster, pose, models[unit], np.random.default_rng((*seed, 1 + k)),
                          calibrations[unit])
      io.write_bin(out / f'{scene_idx:02d}_{k:04d}.bin', *dataset.process(config, raw))
      count += 1
      if progress is not None:
        progress(1)
  if poses_out is not None:
    kitti.write_poses(poses_out, np.concatenate(all_poses))
  return count


SCENE_APART = 10_000.0   # metres between the worlds of two scenes' poses
