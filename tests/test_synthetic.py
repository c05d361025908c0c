"""Synthetic data: determinism, exact ground truth, layouts, baseline."""

import filecmp
import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest
from scipy import spatial

from ssd_jax import geometry
from ssd_jax.data import datasets, groundtruth, io
from ssd_jax.synthetic import dataset, lidar, pushbroom, scene as scene_lib
from tests.conftest import tiny_synthetic_config as tiny_config

ROOT_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture(scope='module')
def tiny_set(tmp_path_factory):
  out = tmp_path_factory.mktemp('synthetic') / 'tiny'
  dataset.generate(tiny_config(), out)
  return out


def _files(root):
  return sorted(os.path.relpath(os.path.join(d, f), root)
                for d, _, fs in os.walk(root) for f in fs)


def test_same_seed_gives_byte_identical_files(tiny_set, tmp_path):
  again = tmp_path / 'again'
  manifest = dataset.generate(tiny_config(), again)
  assert not manifest['reused']
  files = _files(tiny_set)
  assert files == _files(again) and len(files) > 30
  match, mismatch, errors = filecmp.cmpfiles(tiny_set, again, files, shallow=False)
  assert not mismatch and not errors and len(match) == len(files)


def test_different_seeds_give_different_scenes():
  a = scene_lib.make_scene(np.random.default_rng((0, 1, 0)), 80.0)
  b = scene_lib.make_scene(np.random.default_rng((1, 1, 0)), 80.0)
  assert a.style != b.style
  assert a.num_triangles != b.num_triangles
  cfg0, cfg1 = tiny_config(0), tiny_config(1)
  s0 = dataset.make_drive(cfg0, 'test_kitti', 0).scan(0)
  s1 = dataset.make_drive(cfg1, 'test_kitti', 0).scan(0)
  assert abs(len(s0) - len(s1)) > 100 or not np.allclose(np.sort(s0[:, 2])[:100],
                                                         np.sort(s1[:, 2])[:100])


def _off_axis_share(scene, label, min_degrees=10.0):
  """Area share of `label`'s vertical faces turned > min_degrees off the street axes."""
  p = scene.vertices[label].astype(np.float64)[scene.triangles[label]]
  normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
  area = np.linalg.norm(normal, axis=1)
  vertical = (area > 1e-9) & (np.abs(normal[:, 2]) < 0.1 * np.maximum(area, 1e-12))
  _, nearest = spatial.cKDTree(scene.centerline.xy).query(p[vertical].mean(1)[:, :2])
  turn = np.degrees(np.arctan2(normal[vertical, 1], normal[vertical, 0])
                    - scene.centerline.heading[nearest])
  off = np.abs((turn + 45.0) % 90.0 - 45.0) > min_degrees
  return float(np.sum(area[vertical] * off) / np.sum(area[vertical]))


def test_scene_options_add_turned_objects():
  rng = lambda seed: np.random.default_rng((seed, 9))
  plain = [scene_lib.make_scene(rng(k), 80.0) for k in range(3)]
  varied = [scene_lib.make_scene(rng(k), 80.0, clutter_scale=5.0, varied_objects=True)
            for k in range(3)]
  bare = scene_lib.make_scene(rng(0), 80.0, clutter_scale=0.0)
  clutter = scene_lib.Label.CLUTTER
  assert clutter not in bare.triangles and len(plain[0].triangles[clutter]) > 0
  # The street layout is drawn before any object, so it does not change with the options.
  assert all(p.style.road_half_width == v.style.road_half_width for p, v in zip(plain, varied))
  assert (sum(len(v.triangles[clutter]) for v in varied)
          > 4 * sum(len(p.triangles[clutter]) for p in plain))
  for p, v in zip(plain, varied):
    # Default cars are parked along the curb (yaw ~ N(0, 1.7 deg)); half of the varied
    # ones are turned by up to 34 deg. Varied clutter faces every way.
    assert _off_axis_share(p, scene_lib.Label.CAR) < 0.02
    assert _off_axis_share(v, scene_lib.Label.CAR) > 0.15
    assert _off_axis_share(v, clutter) > 0.5
  bad = tiny_config()
  bad.scene.clutter_scale = -1.0
  with pytest.raises(dataset.SyntheticConfigError, match=r'scene.clutter_scale must be >= 0'):
    dataset.check_config(bad)


def _overlap(cloud1, cloud2, t_12, radius=0.3):
  """Fraction of cloud-2 points within radius of cloud 1 after mapping by T_12."""
  dist, _ = spatial.cKDTree(cloud1).query(geometry.apply_transform(t_12, cloud2.astype(float)))
  return float(np.mean(dist < radius))


def test_kitti_style_pairs_overlap_under_ground_truth(tiny_set):
  folder = tiny_set / 'test_kitti' / '00'
  pairs = groundtruth.read_groundtruths(folder / 'groundtruths.txt')
  assert len(pairs) >= 5
  overlaps = []
  for p in pairs:
    c1, c2 = (io.read_cloud(folder / f'{i:06d}.bin') for i in (p.idx1, p.idx2))
    assert np.linalg.norm(p.transform[:3, 3]) < 10.0
    overlaps.append(_overlap(c1, c2, p.transform))
  assert min(overlaps) >= 0.5, overlaps
  # The ground truth matters: a 5 degree yaw error loses most non-ground overlap.
  wrong = geometry.make_transform(geometry.rotation_z(np.radians(5.0)), np.zeros(3)) @ pairs[0].transform
  c1, c2 = (io.read_cloud(folder / f'{i:06d}.bin') for i in (pairs[0].idx1, pairs[0].idx2))
  assert _overlap(c1, c2, wrong) < overlaps[0] - 0.15


def test_kitti_style_clouds_have_normals_and_poses(tiny_set):
  folder = tiny_set / 'test_kitti' / '00'
  raw = np.fromfile(folder / '000000.bin', '<f4').reshape(-1, 6)
  assert io.detect_bin_format(raw.ravel(), 'x') == 'xyzn'
  np.testing.assert_allclose(np.linalg.norm(raw[:, 3:], axis=1), 1.0, atol=1e-4)
  # normals face the sensor at the origin
  assert np.mean(np.einsum('ij,ij->i', raw[:, 3:], -raw[:, :3]) >= 0) > 0.99
  # 0.2 m voxel grid: no two points closer than the voxel's reach allows in bulk
  d, _ = spatial.cKDTree(raw[:, :3]).query(raw[:, :3], k=2)
  assert np.median(d[:, 1]) > 0.1
  poses = np.loadtxt(folder / 'poses.txt').reshape(-1, 3, 4)
  assert len(poses) == len(list(folder.glob('*.bin')))
  np.testing.assert_allclose(poses[:, :, :3] @ poses[:, :, :3].transpose(0, 2, 1),
                             np.broadcast_to(np.eye(3), (len(poses), 3, 3)), atol=1e-6)


def test_kitti_style_random_yaw_turns_scans_and_keeps_ground_truth(tiny_set, tmp_path):
  config = tiny_config()
  config.train.num_scenes = config.test_oxford.num_scenes = config.clusters.num_scenes = 0
  config.test_kitti.random_yaw = True
  dataset.generate(config, tmp_path / 'yaw')
  plain_dir, yaw_dir = tiny_set / 'test_kitti' / '00', tmp_path / 'yaw' / 'test_kitti' / '00'
  plain = groundtruth.read_groundtruths(plain_dir / 'groundtruths.txt')
  turned = groundtruth.read_groundtruths(yaw_dir / 'groundtruths.txt')
  assert [(p.idx1, p.idx2) for p in plain] == [(p.idx1, p.idx2) for p in turned]
  yaws = []
  for p, q in zip(plain, turned):
    a1, a2, b1, b2 = (io.read_cloud(d / f'{i:06d}.bin')[:, :3] for d, i in (
        (plain_dir, p.idx1), (plain_dir, p.idx2), (yaw_dir, q.idx1), (yaw_dir, q.idx2)))
    assert len(a2) == len(b2)
    # Scan 1 is the plain one turned about z through the sensor: same ranges and heights.
    np.testing.assert_allclose(np.linalg.norm(b1[:, :2], axis=1),
                               np.linalg.norm(a1[:, :2], axis=1), atol=1e-4)
    np.testing.assert_allclose(b1[:, 2], a1[:, 2], atol=1e-5)
    turn = np.linalg.lstsq(a1, b1, rcond=None)[0].T
    # Scan 2 under the new ground truth lands where the plain scan 2 lands, turned alike.
    np.testing.assert_allclose(geometry.apply_transform(q.transform, b2),
                               geometry.apply_transform(p.transform, a2) @ turn.T, atol=1e-3)
    yaws.append(np.degrees(np.arctan2(q.transform[1, 0], q.transform[0, 0])))
  # The pairs' relative yaws are spread, no longer near 0 or 180 degrees only.
  assert np.ptp(np.abs(yaws)) > 60, yaws


def test_oxford_style_models(tiny_set):
  root = tiny_set / 'test_oxford'
  pairs = groundtruth.read_groundtruths(root / 'groundtruths.txt')
  for p in pairs:
    c1, c2 = (io.read_cloud(root / 'test_models' / f'{i}.bin') for i in (p.idx1, p.idx2))
    assert c1.shape == c2.shape == (4096, 3)
    assert len(np.unique(c1, axis=0)) == len(c1)   # no repeated points, as the real models
    assert np.linalg.norm(c1[:, :2], axis=1).max() <= 15.0   # crop_radius of the tiny set
    assert _overlap(c1, c2, p.transform) >= 0.4
  # models are randomly rotated: the relative yaw is not just the driving direction
  yaws = [np.degrees(np.arctan2(p.transform[1, 0], p.transform[0, 0])) for p in pairs]
  assert np.std(yaws) > 20


def test_spinning_oxford_variant_and_a_wrong_ground_truth(tiny_set, tmp_path):
  config = tiny_config()
  config.train.num_scenes = config.clusters.num_scenes = 0
  config.test_oxford.sensor = 'spinning'   # the models of the results before the switch
  config.test_oxford.crop_radius, config.test_oxford.spacing = 30.0, 10.0
  dataset.generate(config, tmp_path / 'spin')
  root = tmp_path / 'spin' / 'test_oxford'
  pairs = groundtruth.read_groundtruths(root / 'groundtruths.txt')
  assert len(pairs) >= 3
  for p in pairs:
    c1, c2 = (io.read_cloud(root / 'test_models' / f'{i}.bin') for i in (p.idx1, p.idx2))
    assert c1.shape == c2.shape == (4096, 3) and len(np.unique(c1, axis=0)) == len(c1)
    assert _overlap(c1, c2, p.transform) >= 0.4
  # One spinning scan, not lines accumulated along a pass: other models than the default's.
  default = io.read_cloud(tiny_set / 'test_oxford' / 'test_models' / '0.bin')
  assert not np.array_equal(default, io.read_cloud(root / 'test_models' / '0.bin'))
  root = tiny_set / 'test_oxford'
  pairs = groundtruth.read_groundtruths(root / 'groundtruths.txt')
  # A 5 degree yaw error in the ground truth loses overlap.
  c1, c2 = (io.read_cloud(root / 'test_models' / f'{i}.bin') for i in (pairs[0].idx1, pairs[0].idx2))
  wrong = geometry.make_transform(geometry.rotation_z(np.radians(5.0)), np.zeros(3)) @ pairs[0].transform
  assert _overlap(c1, c2, wrong) < _overlap(c1, c2, pairs[0].transform) - 0.1
  bad = tiny_config()
  bad.test_oxford.sensor = 'spinnning'
  with pytest.raises(dataset.SyntheticConfigError, match="test_oxford.sensor must be one of"):
    dataset.check_config(bad)
  short = tiny_config()
  short.test_oxford.crop_radius = 30.0   # 80 m street, 30 m of margins, 60 m submaps
  with pytest.raises(dataset.SyntheticConfigError, match='holds no whole push-broom submap'):
    dataset.check_config(short)
  empty = tiny_config()
  for split in dataset.SPLITS:
    empty[split].num_scenes = 0
  with pytest.raises(dataset.SyntheticConfigError, match='nothing to generate'):
    dataset.check_config(empty)


def test_training_folder_reads_as_oxford_index(tiny_set):
  entries = io.read_oxford_index(tiny_set / 'train' / 'train.txt')
  poses = np.loadtxt(tiny_set / 'train' / '00' / 'poses.txt').reshape(-1, 3, 4)
  assert len(entries) == len(poses)
  for k, e in enumerate(entries):
    assert k not in e.positives and set(e.positives) <= set(e.non_negatives)
    for j in e.positives:
      assert np.linalg.norm(poses[k, :, 3] - poses[j, :, 3]) < 10.0
  ds = datasets.CloudDataset.from_source(tiny_set / 'train', min_points=64)
  assert ds.batch(0, 0, 2, 512).shape == (2, 512, 3)


def test_cluster_pairs(tiny_set):
  lines = (tiny_set / 'clusters' / 'filenames.txt').read_text().splitlines()
  labels = [int(l.split()[-1]) for l in lines[1:]]
  assert len(labels) == 6 and sum(labels) == 3
  for i in range(6):
    for part in (0, 1):
      pts = io.read_cloud(tiny_set / 'clusters' / f'{i}_{part}.bin')
      assert len(pts) >= 16 and np.linalg.norm(pts, axis=1).max() < 4.0


def test_reuse_and_config_errors(tiny_set, tmp_path):
  before = (tiny_set / 'synthetic.json').stat().st_mtime_ns
  assert dataset.generate(tiny_config(), tiny_set)['reused']
  assert (tiny_set / 'synthetic.json').stat().st_mtime_ns == before
  with pytest.raises(dataset.SyntheticConfigError, match='different config'):
    dataset.generate(tiny_config(seed=3), tiny_set)
  # A dataset written before a config key existed is reused while the key keeps the value
  # it implied, and refused when the config asks for another.
  old = tmp_path / 'old'
  shutil.copytree(tiny_set, old)
  manifest = json.loads((old / 'synthetic.json').read_text())
  del manifest['config']['test_kitti']['random_yaw']
  (old / 'synthetic.json').write_text(json.dumps(manifest))
  assert dataset.generate(tiny_config(), old)['reused']
  turned = tiny_config()
  turned.test_kitti.random_yaw = True
  with pytest.raises(dataset.SyntheticConfigError, match='different config'):
    dataset.generate(turned, old)
  bad = tiny_config()
  bad.test_kitti.spacing = -1.0
  with pytest.raises(dataset.SyntheticConfigError, match=r'test_kitti.spacing must be > 0'):
    dataset.check_config(bad)
  bad = tiny_config()
  bad.lidar.azimuth_step = 0.0
  with pytest.raises(dataset.SyntheticConfigError, match=r'lidar: azimuth_step must be in'):
    dataset.check_config(bad)
  bad = tiny_config()
  bad.lidar.beams = 3
  with pytest.raises(dataset.SyntheticConfigError, match='unknown LiDAR settings'):
    dataset.check_config(bad)


@pytest.mark.multiprocess
def test_cli_reports_bad_config_without_traceback(tmp_path):
  proc = subprocess.run(
      [sys.executable, '-m', 'experiments.data.make_synthetic', f'--out={tmp_path / "x"}',
       '--config=configs/data/synthetic_small.py', '--config.clusters.num_pairs=3'],
      capture_output=True, text=True, cwd=ROOT_DIR)
  assert proc.returncode != 0
  assert 'error: clusters.num_pairs must be even' in proc.stderr
  assert 'Traceback' not in proc.stderr


def test_lidar_on_flat_ground_matches_geometry():
  """An infinite plane seen by a perfect sensor: every return lies on it, along the beams."""
  rng = np.random.default_rng(0)
  verts = np.array([[-500, -500, 0], [500, -500, 0], [500, 500, 0], [-500, 500, 0]], np.float32)
  plane = scene_lib.Scene(None, None, 0.0, {scene_lib.Label.GROUND: verts},
                          {scene_lib.Label.GROUND: np.array([[0, 1, 2], [0, 2, 3]], np.uint32)})
  model = lidar.LidarModel(range_noise=0.0, dropout=0.0, azimuth_step=1.0)
  pose = np.eye(4)
  pose[2, 3] = 1.73
  pts, labels = lidar.scan(lidar.Raycaster(plane), pose, model, rng)
  assert np.all(labels == scene_lib.Label.GROUND)
  np.testing.assert_allclose(pts[:, 2], -1.73, atol=1e-3)
  el = np.degrees(np.arctan2(pts[:, 2], np.linalg.norm(pts[:, :2], axis=1)))
  # beams above the horizon never hit; the lowest beam is at -24.33 degrees
  assert el.max() < 0 and abs(el.min() + 24.33) < 0.01
  r = np.linalg.norm(pts, axis=1)
  assert r.min() >= model.min_range and r.max() <= model.max_range


def test_pushbroom_lines_on_a_known_street():
  """Ground z = 0 and a wall at y = 5 m, a perfect line scanner 2 m up driven along x:
  one line of returns per pose, across the street, each ray where geometry puts it."""
  ground = np.array([[-100, -100, 0], [100, -100, 0], [100, 100, 0], [-100, 100, 0]], np.float32)
  wall = np.array([[-100, 5, -1], [100, 5, -1], [100, 5, 100], [-100, 5, 100]], np.float32)
  quad = np.array([[0, 1, 2], [0, 2, 3]], np.uint32)
  street = scene_lib.Scene(None, None, 0.0,
                           {scene_lib.Label.GROUND: ground, scene_lib.Label.BUILDING: wall},
                           {scene_lib.Label.GROUND: quad, scene_lib.Label.BUILDING: quad})
  model = pushbroom.PushbroomModel(range_noise=0.0, dropout=0.0, angular_step=1.0)
  xs = np.arange(0.0, 10.01, 0.5)
  poses = np.tile(np.eye(4), (len(xs), 1, 1))
  poses[:, 0, 3], poses[:, 2, 3] = xs, 2.0
  pts, labels, lines = pushbroom.accumulate(lidar.Raycaster(street), poses, model,
                                            np.random.default_rng(0))
  np.testing.assert_allclose(pts[:, 0], xs[lines], atol=1e-4)   # lines across the street
  assert sorted(set(lines.tolist())) == list(range(len(xs)))
  on_ground = labels == scene_lib.Label.GROUND
  np.testing.assert_allclose(pts[on_ground, 2], 0.0, atol=1e-4)
  np.testing.assert_allclose(pts[~on_ground, 1], 5.0, atol=1e-4)
  # Per line, the count the geometry predicts: a ray down (cos a > 0) meets the ground
  # at y = 2 tan a unless the wall comes first; a ray towards +y meets the wall at range
  # 5 / sin a; anything beyond 50 m or into the sky is lost.
  a = model.angles()
  t_ground = np.where(np.cos(a) > 1e-9, 2.0 / np.maximum(np.cos(a), 1e-9), np.inf)
  t_wall = np.where(np.sin(a) > 1e-9, 5.0 / np.maximum(np.sin(a), 1e-9), np.inf)
  t = np.minimum(t_ground, t_wall)
  hits = (t >= model.min_range) & (t <= model.max_range)
  expected_wall = int((hits & (t_wall < t_ground)).sum())
  assert np.bincount(lines).tolist() == [int(hits.sum())] * len(xs)
  assert np.bincount(lines[~on_ground]).tolist() == [expected_wall] * len(xs)
  # A pose the vehicle misreports by 0.1 m sideways moves its line by 0.1 m, nothing else.
  moved = poses.copy()
  moved[:, 1, 3] += 0.1
  shifted, _, _ = pushbroom.accumulate(lidar.Raycaster(street), poses, model,
                                       np.random.default_rng(0), reported_poses=moved)
  np.testing.assert_allclose(shifted - pts, np.broadcast_to([0, 0.1, 0], pts.shape), atol=1e-6)
  with pytest.raises(ValueError, match='angular_step'):
    pushbroom.PushbroomModel(angular_step=0.0)
  # The checks both simulated sensors share (lidar.check_sensor_fields), named per field.
  for sensor in (pushbroom.PushbroomModel, lidar.LidarModel):
    with pytest.raises(ValueError, match='need 0 <= min_range < max_range, got 90'):
      sensor(min_range=90.0)
    with pytest.raises(ValueError, match=r'glass_dropout must be in \[0, 1\), got 1.0'):
      sensor(glass_dropout=1.0)
    with pytest.raises(ValueError, match='range_noise must be >= 0, got -0.1'):
      sensor(range_noise=-0.1)
