"""Label-free adaptation (experiments.adapt): fine-tune the shipped model on a folder of
unlabeled scans, export it with its card, register with it."""

import collections
import dataclasses
import os
import subprocess
import sys

import jax
import numpy as np
import pytest

from ssd_jax import geometry, pretrained
from ssd_jax.data import io, mined_pairs, registration_sets
from ssd_jax.evaluation import feature_store
from ssd_jax.registration import bev, metrics, pipeline
from ssd_jax.adaptation import keypoint_choice
from ssd_jax.registration import cloud_features
from ssd_jax.registration import options as options_lib
from ssd_jax.registration import keypoints as keypoints_lib
from ssd_jax.synthetic import cross_sensor
from tests.conftest import shared_path, tiny_cross_sensor_config

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.multiprocess
@pytest.mark.slow
def test_adapt_a_tiny_run_exports_a_model_that_registers(synthetic_root, tmp_path):
  out, scans = tmp_path / 'mine', tmp_path / 'drive'
  cross_sensor.write_sensor_scans(tiny_cross_sensor_config(), 'vlp16', scans, num_scenes=1,
                                  spacing=10.0)
  for f in sorted(scans.glob('*.bin'))[4:]:   # 4 scans of a drive, 10 m apart
    f.unlink()
  cmd = [sys.executable, '-m', 'experiments.adapt', f'--scans={scans}',
         f'--out={out}', '--steps=2', '--config.train.checkpoint_every=1',
         '--config.data.num_points=512', '--config.model.num_clusters=64',
         '--config.progress_bar=False']
  run = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
  assert run.returncode == 0, run.stderr[-3000:]
  assert f'wrote {out}: {pretrained.DEFAULT} adapted on' in run.stdout
  card = (out / 'MODEL_CARD.md').read_text()
  assert f'| base model | `{pretrained.DEFAULT}` |' in card
  assert '2 steps' in card and 'experiments.adapt' in card
  # The drive's pairs were mined first and trained on.
  kept = mined_pairs.read_kept(str(out / 'mined_pairs.csv'))
  assert f'| mined pairs | {len(kept)} (`{out / "mined_pairs.csv"}`) (classical teacher, ' \
      f'gaps 1,2,4,8: ' in card
  assert 'two-view training' in card
  # Its keypoint domain chosen on the mined pairs, as the card says.
  adapted_domain = pretrained.load(str(out)).keypoints
  assert f"'{adapted_domain}' points" in card.split('| keypoints |')[1].splitlines()[0]
  adapted, base = pretrained.load(str(out)), pretrained.load(pretrained.DEFAULT)
  assert adapted.step == 2
  # Every weight starts from the default model (init_scope 'model'), the detector's too, and
  # moved a little.
  moved = jax.tree.map(lambda a, b: float(np.abs(np.asarray(a) - np.asarray(b)).max()),
                       adapted.variables['params'], base.variables['params'])
  assert 0 < max(jax.tree.leaves(moved)) < 0.05
  pair = registration_sets.read_registration_set(synthetic_root / 'test_kitti')[0]
  reg, _, _ = pipeline.register(target=io.read_cloud(pair.cloud1),
                                source=io.read_cloud(pair.cloud2), model=adapted,
                                options=options_lib.Options.paper('learned'))
  assert metrics.registration_errors(pair.transform, reg.transform)['success']


@pytest.mark.multiprocess
def test_adapt_refuses_a_missing_folder(tmp_path):
  run = subprocess.run([sys.executable, '-m', 'experiments.adapt', f'--scans={tmp_path / "no"}',
                        f'--out={tmp_path / "o"}'], cwd=ROOT, capture_output=True, text=True,
                       timeout=120)
  assert run.returncode == 1 and run.stderr.strip().splitlines()[-1].startswith(
      'error: --scans:'), run.stderr[-2000:]


@pytest.mark.multiprocess
@pytest.mark.parametrize('flag, message', [
    ('--config.mining.widen_rounds=-1', 'error: --config.mining.widen_rounds must be 0 or more'),
    ('--config.mining.max_scans=2', 'error: max_scans must be 3 or more')])
def test_adapt_refuses_a_wrong_mining_setting(tmp_path, flag, message):
  scans = tmp_path / 'drive'
  scans.mkdir()
  for k in range(3):
    np.save(scans / f'{k}.npy', np.random.default_rng(k).uniform(-20, 20, (3000, 3)))
  run = subprocess.run([sys.executable, '-m', 'experiments.adapt', f'--scans={scans}',
                        f'--out={tmp_path / "o"}', flag], cwd=ROOT, capture_output=True,
                       text=True, timeout=120)
  assert run.returncode == 1 and run.stderr.strip().splitlines()[-1].startswith(message), \
      run.stderr[-2000:]


def _street(seed=0):
  """A flat ground (0.3 m grid, 60 x 60 m) with 8 walls 2-4 m high: [N, 3] metres."""
  rng = np.random.default_rng(seed)
  g = np.arange(-30, 30, 0.3)
  ground = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
  ground = np.column_stack([ground, rng.normal(0, 0.02, len(ground))])
  walls = []
  for _ in range(8):
    x0, y0, yaw, height = rng.uniform(-25, 25), rng.uniform(-25, 25), rng.uniform(0, np.pi), \
        rng.uniform(2, 4)
    s, z = np.meshgrid(np.arange(0, 8, 0.2), np.arange(0, height, 0.2))
    walls.append(np.column_stack([x0 + s.ravel() * np.cos(yaw), y0 + s.ravel() * np.sin(yaw),
                                  z.ravel()]))
  return np.concatenate([ground, *walls]).astype(np.float32)


def test_structure_keypoints_are_the_farthest_points_above_the_ground(tmp_path):
  cloud = _street()
  ours = pretrained.load('ours')
  structure = dataclasses.replace(ours, keypoints='structure')
  everywhere, _ = cloud_features.compute_keypoints(cloud, 'auto', ours)
  above, _ = cloud_features.compute_keypoints(cloud, 'auto', structure)
  np.testing.assert_array_equal(everywhere, keypoints_lib.farthest_point_keypoints(cloud, 1024))
  assert (cloud[everywhere, 2] < 0.1).mean() > 0.5          # mostly ground
  height = bev.height_above_ground(cloud)
  assert len(above) == 1024 and (height[above] > bev.HEIGHT[0]).all()
  assert (cloud[above, 2] > 0.3).all()                       # on the walls
  # The register defaults' two levels and the evaluation's 'structure' rows agree.
  levels = cloud_features.feature_levels(cloud.astype(np.float64), 'auto', 'learned', structure)
  np.testing.assert_array_equal(levels.keypoints(1), above)
  assert len(levels.keypoints(0)) == 512 and (height[levels.keypoints(0)] > 0.4).all()
  coarse, idx = (level() for level in cloud_features.auto_levels(cloud, 'structure', 512))
  np.testing.assert_array_equal(idx, above)
  np.testing.assert_array_equal(coarse, levels.keypoints(0))
  np.save(tmp_path / 'street.npy', cloud)
  np.testing.assert_array_equal(
      feature_store.FeatureStore({}).keypoints(tmp_path / 'street.npy', 'structure'), above)
  # A cloud with too little rising from its ground keeps all its points to sample from.
  flat = cloud[cloud[:, 2] < 0.1]
  flat = np.concatenate([flat, [[0, 0, 1.0]] * 10]).astype(np.float32)
  np.testing.assert_array_equal(cloud_features.keypoint_domain(flat, 'structure'),
                                np.arange(len(flat)))
  with pytest.raises(ValueError, match="keypoint domain must be one of .*got 'ground'"):
    cloud_features.keypoint_domain(cloud, 'ground')


def test_choice_pairs_reach_past_the_miners_gaps_by_chaining_two_kept_pairs():
  """A drive of 40 scans mined at gaps 1, 2 and 4 (kept), 8 (not kept): G = 4, the largest
  gap with `count` kept pairs, so the choice takes chains of two kept pairs at gaps 5, 6
  and 8 (no two kept gaps sum to 7), as many of each, spread over the drive."""
  def pair(i, gap, kept=True):
    shift = np.eye(4)
    shift[0, 3] = 6.0 * gap
    return mined_pairs.MinedPair(f's{i:02d}', f's{i + gap:02d}', gap, shift, 0.5, True, kept)
  pairs = [pair(i, g) for g in (1, 2, 4) for i in range(40 - g)]
  pairs += [pair(i, 8, kept=False) for i in range(32)]
  picked = keypoint_choice.choice_pairs(pairs, 12)
  assert sorted(collections.Counter(p.gap for p in picked).items()) == [(5, 4), (6, 4), (8, 4)]
  assert len({(p.cloud1, p.cloud2) for p in picked}) == 12
  for p in picked:     # each composed of its links: 6 m a scan
    assert p.transform[0, 3] == pytest.approx(6.0 * p.gap)
    assert int(p.cloud2[1:]) - int(p.cloud1[1:]) == p.gap
  firsts = sorted(int(p.cloud1[1:]) for p in picked if p.gap == 8)
  assert firsts[0] == 0 and firsts[-1] == 39 - 8      # spread over the drive
  assert keypoint_choice.choose(None, [pair(0, 1, kept=False)], np.load) is None


def test_the_choice_keeps_the_structure_unless_all_points_register_more(monkeypatch):
  pairs = [mined_pairs.MinedPair(f's{i:02d}', f's{i + g:02d}', g, np.eye(4), 0.5, True, True)
           for g in (1, 2) for i in range(30)]
  for counts, want in (({'all': 12, 'structure': 12}, 'structure'),
                       ({'all': 13, 'structure': 12}, 'all'),
                       ({'all': 3, 'structure': 7}, 'structure')):
    monkeypatch.setattr(keypoint_choice, 'registered',
                        lambda model, sample, read, domain, counts=counts: counts[domain])
    choice = keypoint_choice.choose(None, pairs, np.load, count=8)
    assert choice.keypoints == want and choice.registered == counts, counts


@pytest.mark.real_data
@pytest.mark.slow
def test_the_choice_counts_the_pairs_each_domain_registers_against_the_miners_transforms(
    tmp_path):
  scan = io.read_cloud(shared_path('kitti_object_velodyne', '000000.bin')).astype(np.float64)
  scan = scan[np.linalg.norm(scan[:, :2], axis=1) < 40]
  np.save(tmp_path / 'a.npy', scan[::2])
  pairs = []
  for n, (yaw, shift) in enumerate(((30.0, [3.0, -2.0, 0.0]), (-90.0, [-4.0, 1.0, 0.0]))):
    t = geometry.make_transform(geometry.rotation_z(np.radians(yaw)), np.array(shift))
    np.save(tmp_path / f'{n}.npy', (scan[1::2] - t[:3, 3]) @ t[:3, :3])
    pairs.append(mined_pairs.MinedPair(str(tmp_path / 'a.npy'), str(tmp_path / f'{n}.npy'),
                                       2 + n, t, 0.9, True, True))
  # A label 10 m off: no domain registers it against that.
  off = geometry.make_transform(np.eye(3), np.array([10.0, 0.0, 0.0]))
  wrong = dataclasses.replace(pairs[0], gap=1, transform=pairs[0].transform @ off)
  pairs.append(wrong)
  # Each pair on its own: the choice registers the pairs it is given, against their labels.
  counts = {domain: keypoint_choice.registered(pretrained.load('ours'), pairs, np.load, domain)
            for domain in ('all', 'structure')}
  assert counts == {'all': 2, 'structure': 2}
