"""Write a synthetic dataset in the real datasets' folder layouts.

    OUT/
      train/train.txt               3DFeat-Net Oxford index: file | positives | non-negatives
      train/<seq>/<frame>.bin       N x 6 (xyz + normals), 0.2 m voxel grid, sensor frame
      train/<seq>/poses.txt         KITTI-style 3 x 4 sensor poses in the scene frame
      test_kitti/<seq>/<frame>.bin  KITTI-style test set: a cloud every ~10 m, pairs < 10 m
      test_kitti/<seq>/groundtruths.txt
      test_kitti/<seq>/poses.txt
      test_oxford/test_models/<idx>.bin   Oxford-style: 16,384 points, randomly rotated
      test_oxford/groundtruths.txt
      clusters/filenames.txt        descriptor-matching pairs (docs/method.md §4)
      clusters/<i>_0.bin, <i>_1.bin 4 m crops centred on a random point, randomly rotated
      synthetic.json                the config and seed that made it, and counts

Every split uses its own scenes. Each scene, drive and scan draws from its own
seed, (seed, split, scene, scan), so the files are byte-identical for a seed and
independent of the order of generation.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os
from pathlib import Path
import shutil
from typing import Callable

import numpy as np
from scipy import spatial

from ssd_jax import geometry
from ssd_jax.config_tools import upgrade
from ssd_jax.infra import errors
from ssd_jax.data import datasets, groundtruth, io, kitti, preprocess
from ssd_jax.registration import keypoints
from ssd_jax.synthetic import lidar, pushbroom, scene as scene_lib, trajectory

SPLITS = {'train': 1, 'test_kitti': 2, 'test_oxford': 3, 'clusters': 4}
MANIFEST = 'synthetic.json'
# Sub-streams of a drive's seed (seed, split, scene): scan k uses 1 + k.
_CALIBRATION_STREAM = 0
_MODEL_ROTATION_STREAM = 1 << 30
_PUSHBROOM_STREAM = (1 << 30) + 1
OXFORD_SENSORS = ('spinning', 'pushbroom')
FORMAT_VERSION = 1


class SyntheticConfigError(errors.UserError):
  """A synthetic-data config value is out of range."""


def check_config(config) -> None:
  """Refuse values that would make an empty or meaningless dataset."""
  def positive(path, value, allow_zero=False):
    if not (value > 0 or (allow_zero and value == 0)):
      raise SyntheticConfigError(f'{path} must be {">= 0" if allow_zero else "> 0"}, got {value!r}')
  positive('scene_length', config.scene_length)
  if config.scene_length < 60:
    raise SyntheticConfigError(f'scene_length must be >= 60 m, got {config.scene_length}')
  for split in SPLITS:
    positive(f'{split}.num_scenes', config[split].num_scenes, allow_zero=True)
    positive(f'{split}.spacing', config[split].spacing)
  positive('voxel_size', config.voxel_size, allow_zero=True)
  positive('scene.clutter_scale', config.scene.clutter_scale, allow_zero=True)
  positive('normal_radius', config.normal_radius)
  positive('test_oxford.num_points', config.test_oxford.num_points)
  positive('test_oxford.voxel_size', config.test_oxford.voxel_size, allow_zero=True)
  if config.test_oxford.sensor not in OXFORD_SENSORS:
    raise SyntheticConfigError(f'test_oxford.sensor must be one of {OXFORD_SENSORS}, got '
                               f'{config.test_oxford.sensor!r}')
  positive('test_oxford.line_spacing', config.test_oxford.line_spacing)
  if (config.test_oxford.sensor == 'pushbroom' and config.test_oxford.num_scenes
      and config.scene_length - 2 * trajectory.MARGIN < 2 * config.test_oxford.crop_radius):
    raise SyntheticConfigError(
        f'test_oxford: a pass of scene_length {config.scene_length} m (less '
        f'{2 * trajectory.MARGIN:.0f} m of margins) holds no whole push-broom submap of 2 x '
        f'crop_radius = {2 * config.test_oxford.crop_radius} m; lower test_oxford.crop_radius '
        'or raise scene_length')
  positive('clusters.num_pairs', config.clusters.num_pairs, allow_zero=True)
  if config.clusters.centers not in ('random', 'iss'):
    raise SyntheticConfigError(f"clusters.centers must be 'random' or 'iss', got "
                               f'{config.clusters.centers!r}')
  if config.clusters.num_pairs % 2:
    raise SyntheticConfigError(f'clusters.num_pairs must be even (half match), got '
                               f'{config.clusters.num_pairs}')
  if not any(config[split].num_scenes for split in SPLITS):
    raise SyntheticConfigError('nothing to generate: num_scenes is 0 in every split ('
                               + ', '.join(SPLITS) + ')')
  try:
    lidar.LidarModel.from_config(config.lidar)
  except (ValueError, TypeError) as e:
    raise SyntheticConfigError(f'lidar: {e}') from None


@dataclasses.dataclass
class Drive:
  """One scene driven through: sensor poses T_world_sensor [P, 4, 4] and a scanner."""
  seed: tuple[int, ...]
  poses: np.ndarray
  raycaster: lidar.Raycaster
  model: lidar.LidarModel

  def scan(self, k: int) -> np.ndarray:
    """Raw scan k: [M, 3] float32 metres in the sensor frame."""
    return self.scan_with_labels(k)[0]

  def scan_with_labels(self, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Raw scan k and the `scene.Label` of each point."""
    # One physical sensor per drive: its calibration error is the same in every scan.
    calibration = self.model.calibration(
        np.random.default_rng((*self.seed, _CALIBRATION_STREAM)))
    return lidar.scan(self.raycaster, self.poses[k], self.model,
                      np.random.default_rng((*self.seed, 1 + k)), calibration)

  @property
  def positions(self) -> np.ndarray:
    return self.poses[:, :3, 3]


def _scene_and_poses(config, split: str, index: int):
  seed = (int(config.seed), SPLITS[split], index)
  rng = np.random.default_rng(seed)
  scene = scene_lib.make_scene(rng, config.scene_length, config.scene.clutter_scale,
                               config.scene.varied_objects)
  split_cfg = config[split]
  poses = trajectory.drive(scene, rng, split_cfg.spacing, config.lidar.mount_height,
                           spacing_jitter=split_cfg.get('spacing_jitter', 0.0))
  return seed, scene, poses


def make_drive(config, split: str, index: int) -> Drive:
  """Scene `index` of `split`, its drive and its scanner."""
  seed, scene, poses = _scene_and_poses(config, split, index)
  return Drive(seed, poses, lidar.Raycaster(scene), lidar.LidarModel.from_config(config.lidar))


def process(config, points: np.ndarray,
            voxel_size: float | None = None) -> tuple[np.ndarray, np.ndarray]:
  """3DFeat-Net's processing with the config's voxel size (or `voxel_size`) and normal
  radius."""
  voxel = config.voxel_size if voxel_size is None else voxel_size
  return preprocess.process_scan(points, voxel, config.normal_radius)


def _write_train(config, out: Path, tick: Callable[[], None]) -> int:
  cfg = config.train
  lines, offset = [], 0
  for seq in range(cfg.num_scenes):
    drive = make_drive(config, 'train', seq)
    folder = out / 'train' / f'{seq:02d}'
    folder.mkdir(parents=True)
    kitti.write_poses(folder / 'poses.txt', drive.poses)
    tree = spatial.cKDTree(drive.positions)
    for k in range(len(drive.poses)):
      points, normals = process(config, drive.scan(k))
      io.write_bin(folder / f'{k:06d}.bin', points, normals)
      pos = tree.query_ball_point(drive.positions[k], cfg.positive_radius)
      non_neg = tree.query_ball_point(drive.positions[k], cfg.non_negative_radius)
      fmt = lambda ids: ' '.join(str(offset + i) for i in sorted(ids) if i != k)
      lines.append(f'{seq:02d}/{k:06d}.bin | {fmt(pos)} | {fmt(non_neg)}')
      tick()
    offset += len(drive.poses)
  if lines:
    (out / 'train' / 'train.txt').write_text('\n'.join(lines) + '\n')
  return offset


def _write_test_kitti(config, out: Path, tick) -> int:
  """KITTI-style sequences in the sensor frame. With `test_kitti.random_yaw` each scan
  is also turned about the sensor's z axis by its own uniform yaw (poses.txt and the
  ground truth follow), so the relative yaw of the pairs covers the whole circle
  instead of the ~0 and ~180 degrees of two passes along a street."""
  cfg, num_pairs = config.test_kitti, 0
  for seq in range(cfg.num_scenes):
    drive = make_drive(config, 'test_kitti', seq)
    folder = out / 'test_kitti' / f'{seq:02d}'
    folder.mkdir(parents=True)
    rng = np.random.default_rng((*drive.seed, _MODEL_ROTATION_STREAM))
    frames = []   # T_world_written of each scan
    for k in range(len(drive.poses)):
      points, normals = process(config, drive.scan(k))
      frame = drive.poses[k]
      if cfg.random_yaw:
        rot = geometry.rotation_z(rng.uniform(-np.pi, np.pi))
        points, normals = points @ rot.T, normals @ rot.T
        frame = frame @ geometry.make_transform(rot.T, np.zeros(3))
      io.write_bin(folder / f'{k:06d}.bin', points, normals)
      frames.append(frame)
      tick()
    frames = np.stack(frames)
    kitti.write_poses(folder / 'poses.txt', frames)
    pairs = [groundtruth.GroundTruthPair(i, j, groundtruth.relative_pose(frames, i, j))
             for i, j in groundtruth.close_pairs(drive.positions, cfg.pair_max_distance)]
    groundtruth.write_groundtruths(folder / 'groundtruths.txt', pairs)
    num_pairs += len(pairs)
  return num_pairs


def _model_voxel_size(raw: np.ndarray, cfg) -> float:
  """The largest grid <= test_oxford.voxel_size, in 5 % steps, whose crop holds at least
  num_points distinct voxels. One spinning scan holds fewer 0.2 m voxels within 30 m
  than the real models (accumulated push-broom maps, a near-regular 0.2 m spacing,
  no repeated point) have points; a slightly finer grid keeps the spacing regular,
  where thinning a much finer grid at random would not."""
  voxel = float(cfg.voxel_size)
  for _ in range(20):
    if len(preprocess.voxel_downsample(raw, voxel)) >= cfg.num_points:
      break
    voxel *= 0.95
  return voxel


def _write_oxford_model(config, path: Path, points: np.ndarray, normals: np.ndarray,
                        rng: np.random.Generator, index: int) -> np.ndarray:
  """Write one Oxford-style model: a random subset of num_points rows of points [M, 3]
  and normals, turned by a random yaw. -> the yaw's rotation [3, 3] (model <- input)."""
  cfg = config.test_oxford
  if len(points) < cfg.num_points:   # would repeat points, which real models never do
    logging.warning('test_oxford model %d: only %d points within %.0f m, fewer than %d; '
                    'some are repeated', index, len(points), cfg.crop_radius, cfg.num_points)
  keep = np.sort(datasets.subsample_indices(rng, len(points), cfg.num_points))
  rot = geometry.rotation_z(rng.uniform(-np.pi, np.pi))
  io.write_bin(path, points[keep] @ rot.T, normals[keep] @ rot.T)
  return rot


def _pushbroom_drive(config, seq: int):
  """Test scene `seq` driven down and back by the line scanner -> (seed, scene, the rng
  the scan noise continues from, (true, reported, leg) line poses as
  `pushbroom.line_poses`, centre lines of the models: every `spacing` metres of each
  pass whose submap of 2 crop_radius metres lies wholly on the pass)."""
  cfg = config.test_oxford
  seed, scene, _ = _scene_and_poses(config, 'test_oxford', seq)
  rng = np.random.default_rng((*seed, _PUSHBROOM_STREAM))
  poses = pushbroom.line_poses(scene, rng, cfg.line_spacing, config.lidar.mount_height)
  xyz, leg = poses[1][:, :3, 3], poses[2]
  stride = max(1, int(round(cfg.spacing / cfg.line_spacing)))
  centres = []
  for side in (0, 1):
    idx = np.flatnonzero(leg == side)
    travelled = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(xyz[idx], axis=0), axis=1))])
    full = (travelled >= cfg.crop_radius) & (travelled <= travelled[-1] - cfg.crop_radius)
    centres += idx[full][::stride].tolist()
  return seed, scene, rng, poses, centres


def _write_test_oxford_pushbroom(config, out: Path, tick) -> int:
  """Oxford test models as RobotCar's: a line scanner's lines accumulated over
  2 crop_radius metres of one traversal (`pushbroom`) and cropped to crop_radius around
  the centre line's position, a model every `spacing` metres of each of the two passes
  down the street, pairs within pair_max_distance."""
  cfg, idx0, all_pairs = config.test_oxford, 0, []
  folder = out / 'test_oxford' / 'test_models'
  folder.mkdir(parents=True)
  sensor = pushbroom.PushbroomModel()
  for seq in range(cfg.num_scenes):
    seed, scene, rng, (true, reported, leg), centres = _pushbroom_drive(config, seq)
    points, _, lines = pushbroom.accumulate(lidar.Raycaster(scene), true, sensor, rng, reported)
    rot_rng = np.random.default_rng((*seed, _MODEL_ROTATION_STREAM))
    xyz, frames = reported[:, :3, 3], []
    for c in centres:
      sub = pushbroom.submap(points, lines, xyz, leg, c, cfg.crop_radius)
      # In the frame the vehicle reported at the centre line, as the real models are,
      # and within crop_radius of it in the plane (the real models end at 30 m).
      local = (sub - reported[c, :3, 3]) @ reported[c, :3, :3]
      local = local[np.linalg.norm(local[:, :2], axis=1) <= cfg.crop_radius]
      pts, normals = process(config, local.astype(np.float32), cfg.voxel_size)
      rot = _write_oxford_model(config, folder / f'{idx0 + len(frames)}.bin', pts, normals,
                                rot_rng, idx0 + len(frames))
      frames.append(reported[c] @ geometry.make_transform(rot.T, np.zeros(3)))
      tick()
    if not frames:   # check_config refuses such lengths; a curved street may still be short
      raise SyntheticConfigError(
          f'test_oxford scene {seq}: no whole push-broom submap of 2 x crop_radius = '
          f'{2 * cfg.crop_radius} m along its passes; lower test_oxford.crop_radius or raise '
          'scene_length')
    frames = np.stack(frames)
    all_pairs += [groundtruth.GroundTruthPair(idx0 + i, idx0 + j, groundtruth.relative_pose(frames, i, j))
                  for i, j in groundtruth.close_pairs(frames[:, :3, 3], cfg.pair_max_distance)]
    idx0 += len(frames)
  if all_pairs:
    groundtruth.write_groundtruths(out / 'test_oxford' / 'groundtruths.txt', all_pairs)
  return len(all_pairs)


def _write_test_oxford(config, out: Path, tick) -> int:
  """Oxford test models: cropped, a fixed point count, each in a random z-rotated frame."""
  if config.test_oxford.sensor == 'pushbroom':
    return _write_test_oxford_pushbroom(config, out, tick)
  cfg, idx0, all_pairs = config.test_oxford, 0, []
  folder = out / 'test_oxford' / 'test_models'
  folder.mkdir(parents=True)
  for seq in range(cfg.num_scenes):
    drive = make_drive(config, 'test_oxford', seq)
    rng = np.random.default_rng((*drive.seed, _MODEL_ROTATION_STREAM))
    frames = []   # T_world_model of each written model
    for k in range(len(drive.poses)):
      raw = drive.scan(k)
      raw = raw[np.linalg.norm(raw[:, :2], axis=1) < cfg.crop_radius]
      points, normals = process(config, raw, _model_voxel_size(raw, cfg))
      rot = _write_oxford_model(config, folder / f'{idx0 + k}.bin', points, normals, rng,
                                idx0 + k)
      frames.append(drive.poses[k] @ geometry.make_transform(rot.T, np.zeros(3)))
      tick()
    frames = np.stack(frames)
    all_pairs += [groundtruth.GroundTruthPair(idx0 + i, idx0 + j, groundtruth.relative_pose(frames, i, j))
                  for i, j in groundtruth.close_pairs(drive.positions, cfg.pair_max_distance)]
    idx0 += len(drive.poses)
  if all_pairs:
    groundtruth.write_groundtruths(out / 'test_oxford' / 'groundtruths.txt', all_pairs)
  return len(all_pairs)


def _crop_cluster(rng, points, normals, center, radius):
  """Points within `radius` of center, relative to it, in a random z-rotated frame."""
  inside = np.linalg.norm(points - center, axis=1) < radius
  rot = geometry.rotation_z(rng.uniform(-np.pi, np.pi))
  return (points[inside] - center) @ rot.T, normals[inside] @ rot.T


def _write_clusters(config, out: Path, tick) -> tuple[int, int]:
  """Matching pairs: one world point seen from two scans < 10 m apart; non-matching:
  points of two scans at least 20 m apart (docs/method.md §4). Centres are random scan
  points (`clusters.centers='random'`, the paper's) or ISS keypoints ('iss')."""
  cfg = config.clusters
  folder = out / 'clusters'
  folder.mkdir(parents=True)
  drives, clouds = [], []
  for seq in range(cfg.num_scenes):
    drive = make_drive(config, 'clusters', seq)
    scans = []
    for k in range(len(drive.poses)):
      points, normals = process(config, drive.scan(k))
      centers = (keypoints.iss(points) if cfg.centers == 'iss' else np.arange(len(points)))
      scans.append((points, normals, centers, spatial.cKDTree(points)))
      tick()
    drives.append(drive)
    clouds.append(scans)
  rng = np.random.default_rng((int(config.seed), SPLITS['clusters'], 1 << 20))
  near = [groundtruth.close_pairs(d.positions, cfg.positive_max_distance) for d in drives]
  far = [[(i, j) for i in range(len(d.poses)) for j in range(i + 1, len(d.poses))
          if np.linalg.norm(d.positions[i] - d.positions[j]) >= cfg.negative_min_distance]
         for d in drives]
  if not any(near) or not any(far):
    raise SyntheticConfigError('clusters: the scenes give no scan pairs closer than '
                               f'{cfg.positive_max_distance} m or none farther than '
                               f'{cfg.negative_min_distance} m; lengthen scene_length')
  half = cfg.num_pairs // 2
  labels = rng.permutation(np.r_[np.ones(half, int), np.zeros(half, int)])
  lines = ['pair\tcluster_0\tcluster_1\tlabel']
  for n, label in enumerate(labels):
    for _ in range(1000):   # rejection sampling of an observed, populated location
      seq = int(rng.integers(cfg.num_scenes))
      pool = near[seq] if label else far[seq]
      if not pool:
        continue
      i, j = pool[rng.integers(len(pool))]
      if rng.uniform() < 0.5:
        i, j = j, i
      pts_i, nrm_i, ctr_i, _ = clouds[seq][i]
      pts_j, nrm_j, ctr_j, tree_j = clouds[seq][j]
      if len(ctr_i) == 0 or len(ctr_j) == 0:
        continue
      c0 = pts_i[ctr_i[rng.integers(len(ctr_i))]]
      if label:
        c1 = geometry.apply_transform(groundtruth.relative_pose(drives[seq].poses, j, i), c0[None])[0]
        if tree_j.query(c1)[0] > cfg.max_surface_distance:
          continue   # not seen from scan j
      else:
        c1 = pts_j[ctr_j[rng.integers(len(ctr_j))]]
      a = _crop_cluster(rng, pts_i, nrm_i, c0, cfg.radius)
      b = _crop_cluster(rng, pts_j, nrm_j, c1, cfg.radius)
      if min(len(a[0]), len(b[0])) >= cfg.min_points:
        break
    else:
      raise SyntheticConfigError(f'clusters: found no valid {"matching" if label else "non-matching"} '
                                 'pair in 1000 tries; lower clusters.min_points')
    io.write_bin(folder / f'{n}_0.bin', *a)
    io.write_bin(folder / f'{n}_1.bin', *b)
    lines.append(f'{n}\t{n}_0.bin\t{n}_1.bin\t{label}')
  (folder / 'filenames.txt').write_text('\n'.join(lines) + '\n')
  return half, half


def count_scans(config) -> int:
  """Scans (push-broom Oxford-style models) the config will simulate, for the progress
  display."""
  pushbroom_oxford = config.test_oxford.sensor == 'pushbroom'
  return sum(len(_pushbroom_drive(config, seq)[4]) if split == 'test_oxford' and pushbroom_oxford
             else len(_scene_and_poses(config, split, seq)[2])
             for split in SPLITS for seq in range(config[split].num_scenes))


def generate(config, out: str | os.PathLike, progress: Callable[[int], None] | None = None,
             overwrite: bool = False) -> dict:
  """Write the whole dataset to `out` atomically (built in `out.partial`, then renamed).

  Returns the manifest. If `out` already holds a dataset made from the same config,
  it is reused and nothing is written. `progress(n)` is called after each scan.
  """
  check_config(config)
  out = Path(out)
  settings = json.loads(config.to_json())
  existing = read_manifest(out)
  if existing is not None:
    if (upgrade.upgrade_synthetic(existing['config']) == settings
        and existing['format_version'] == FORMAT_VERSION):
      return {**existing, 'reused': True}
    if not overwrite:
      raise SyntheticConfigError(f'{out} holds a synthetic dataset made with a different config '
                                 'or seed; pass --overwrite or choose another --out')
  elif out.exists() and any(out.iterdir()):
    raise SyntheticConfigError(f'{out} exists and is not a synthetic dataset; choose another --out')
  partial = out.with_name(out.name + '.partial')
  if partial.exists():
    shutil.rmtree(partial)
  partial.mkdir(parents=True)
  tick = (lambda: progress(1)) if progress else (lambda: None)
  counts = {
      'train_clouds': _write_train(config, partial, tick),
      'test_kitti_pairs': _write_test_kitti(config, partial, tick),
      'test_oxford_pairs': _write_test_oxford(config, partial, tick),
  }
  if config.clusters.num_scenes and config.clusters.num_pairs:
    counts['cluster_pairs_matching'], counts['cluster_pairs_non_matching'] = _write_clusters(
        config, partial, tick)
  manifest = {'format_version': FORMAT_VERSION, 'config': settings, 'counts': counts}
  (partial / MANIFEST).write_text(json.dumps(manifest, indent=2, sort_keys=True) + '\n')
  if out.exists():
    shutil.rmtree(out)
  os.replace(partial, out)
  return {**manifest, 'reused': False}


def read_manifest(out: str | os.PathLike) -> dict | None:
  path = Path(out) / MANIFEST
  if not path.is_file():
    return None
  return json.loads(path.read_text())
