"""Cross-sensor test sets (synthetic and real re-scans) and their sensor x distance matrix."""

import csv
import os
import subprocess
import sys

import numpy as np
import pytest
from scipy import spatial

from ssd_jax import sensors
from ssd_jax.configs.evals import cross_sensor as cross_sensor_eval
from ssd_jax.data import io, registration_sets, rescan
from ssd_jax.evaluation import evaluators, feature_store
from ssd_jax.synthetic import cross_sensor, dataset
from tests.conftest import shared_path, tiny_cross_sensor_config

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))




@pytest.fixture(scope='module')
def tiny_set(tmp_path_factory):
  out = tmp_path_factory.mktemp('cross') / 'synthetic'
  cross_sensor.generate(tiny_cross_sensor_config(), out)
  return out


def _overlap(pair):
  """Share of cloud-2 points within 0.3 m of cloud 1 under the ground truth."""
  c1, c2 = io.read_cloud(pair.cloud1), io.read_cloud(pair.cloud2)
  moved = c2 @ pair.transform[:3, :3].T + pair.transform[:3, 3]
  return np.mean(spatial.cKDTree(c1).query(moved)[0] < 0.3)


def test_synthetic_pairs_have_their_units_distances_and_exact_poses(tiny_set):
  pairs = registration_sets.read_registration_set(tiny_set)
  info = registration_sets.read_pair_info(tiny_set)
  assert len(pairs) == 4 and len(info) == 4
  bins = sorted(((info[p.idx1, p.idx2]['sensor2'], info[p.idx1, p.idx2]['distance_m'] >= 10)
                 for p in pairs))
  assert bins == [('front120', False), ('front120', True), ('vlp16', False), ('vlp16', True)]
  for pair in pairs:
    meta = info[pair.idx1, pair.idx2]
    assert 5 <= meta['distance_m'] < 20
    assert meta['sensor1'] == 'hdl64' and meta['sensor2'] in ('vlp16', 'front120')
    assert _overlap(pair) > 0.1, meta         # the true pose lays one scan on the other
    wrong = pair.transform.copy()
    wrong[:3, 3] += 2.0
    assert _overlap(registration_sets.RegistrationPair('', 0, 0, pair.cloud1, pair.cloud2, wrong)) \
        < 0.5 * _overlap(pair)
    c2 = io.read_cloud(pair.cloud2)
    if meta['sensor2'] == 'front120':   # a 120-degree sector in its own frame
      assert np.abs(np.degrees(np.arctan2(c2[:, 1], c2[:, 0]))).max() < 61
  # The same config reuses the set; another one is refused.
  assert cross_sensor.generate(tiny_cross_sensor_config(), tiny_set)['reused']
  other = tiny_cross_sensor_config()
  other.cross_sensor.pairs_per_cell = 2
  with pytest.raises(dataset.SyntheticConfigError, match='different config'):
    cross_sensor.generate(other, tiny_set)


@pytest.mark.parametrize('field, value, message', [
    ('sensors', ('vlp16', 'puck'), "unknown sensor 'puck'"),
    ('distance_bins', ((10.0, 5.0),), 'each bin must be'),
    ('distance_bins', ((5.0, 500.0),), 'longer than a drive'),
])
def test_bad_cross_sensor_configs_are_refused(field, value, message):
  config = tiny_cross_sensor_config()
  config.cross_sensor[field] = value
  with pytest.raises(dataset.SyntheticConfigError, match=message):
    cross_sensor.check_config(config)


@pytest.mark.real_data
def test_real_rescan_by_another_unit(tmp_path):
  source = shared_path('example', 'kitti_00_001554.bin')
  rows = rescan.make_cross_sensor_set([source], tmp_path, ('vlp16',), ((5.0, 10.0),))
  assert len(rows) == 1 and 5 <= rows[0]['distance_m'] < 10
  pair = registration_sets.read_registration_set(tmp_path)[0]
  c2 = io.read_cloud(pair.cloud2)
  # Cloud 2 is in the virtual unit's frame: its points lie near the 16 beams (the voxel
  # grid and noise blur them a little), where the source scan's elevations are spread.
  near = lambda pts: np.mean(np.min(np.abs(np.degrees(np.arctan2(
      pts[:, 2], np.linalg.norm(pts[:, :2], axis=1)))[:, None]
      - sensors.get('vlp16').elevations()[None]), axis=1) < 0.4)
  assert near(c2) > 0.8 > 0.5 > near(io.read_cloud(source))
  assert _overlap(pair) > 0.3
  assert registration_sets.read_pair_info(tmp_path)[pair.idx1, pair.idx2]['sensor2'] == 'vlp16'


def test_pair_info_errors_name_the_file(tmp_path):
  with pytest.raises(io.CloudFileError, match='pairs.tsv: missing'):
    registration_sets.read_pair_info(tmp_path)
  (tmp_path / 'pairs.tsv').write_text('idx1\tidx2\n')
  with pytest.raises(io.CloudFileError, match='the header must be'):
    registration_sets.read_pair_info(tmp_path)


@pytest.mark.slow
def test_cross_sensor_evaluation_writes_the_matrix(tiny_set, tmp_path):
  config = cross_sensor_eval.get_config()
  config.data_root = str(tiny_set.parent)
  config.fpfh_max_nn = 200
  del config.evals['real']
  config.evals.synthetic.dataset = 'synthetic'
  config.evals.synthetic.distance_bins = ((5.0, 10.0), (10.0, 20.0))
  config.evals.synthetic.rows = ('iss+fpfh', 'auto+fpfh+upright+verify+bev', 'open3d', 'bev')
  _, text = evaluators.evaluate(config, tmp_path, log=lambda s: None)
  assert '| method | all | vlp16 | front120 | 5-10 m | 10-20 m |' in text
  assert 'Open3D ISS + FPFH (paper searches)' in text and 'BEV search alone, verified' in text
  assert 'farthest-point kpt + FPFH desc, upright RANSAC, verified with BEV search' in text
  with open(tmp_path / 'synthetic.csv') as f:
    rows = list(csv.DictReader(f))
  # 4 methods x (2 units + all) x (2 bins + all) cells, each with its pair count.
  assert len(rows) == 36 and {r['pairs'] for r in rows if r['unit'] != 'all'
                              and r['distance'] != 'all'} == {'1'}
  assert all(0 <= float(r['success (%)']) <= 100 for r in rows)
  lines = (tmp_path / 'synthetic_pairs.jsonl').read_text().splitlines()
  assert len(lines) == 16 and '"row": "bev"' in lines[-1]


def test_unlabeled_scans_of_one_unit(tmp_path):
  n = cross_sensor.write_sensor_scans(tiny_cross_sensor_config(), 'vlp16', tmp_path, num_scenes=1,
                                      spacing=20.0)
  files = sorted(tmp_path.glob('*.bin'))
  assert n == len(files) >= 3
  pts = io.read_cloud(files[0])
  el = np.degrees(np.arctan2(pts[:, 2], np.linalg.norm(pts[:, :2], axis=1)))
  near = np.min(np.abs(el[:, None] - sensors.get('vlp16').elevations()[None]), axis=1) < 0.5
  assert near.mean() > 0.8 and np.abs(el).max() < 16   # a VLP-16's rings, nothing above


def test_a_mixed_drive_takes_its_units_in_turn(tmp_path):
  n = cross_sensor.write_sensor_scans(tiny_cross_sensor_config(), ['vlp16', 'front120'],
                                      tmp_path, num_scenes=1, spacing=20.0)
  files = sorted(tmp_path.glob('*.bin'))
  assert n == len(files) >= 3
  azimuth = [np.degrees(np.abs(np.arctan2(p[:, 1], p[:, 0]))).max()
             for p in map(io.read_cloud, files)]
  # Even scans the spinning VLP-16 (all round), odd ones the 120-degree unit (+-60 deg).
  assert all(a > 170 for a in azimuth[0::2]) and all(a < 62 for a in azimuth[1::2])


@pytest.mark.multiprocess
def test_make_real_pairs_names_a_bad_unit(tmp_path):
  # An empty data root: the flag is named before the scans are looked for.
  run = subprocess.run([sys.executable, '-m', 'experiments.data.make_real_pairs', '--sensor=vlp32',
                        f'--out={tmp_path}', f'--real={tmp_path}'], cwd=ROOT,
                       capture_output=True, text=True, timeout=120)
  assert run.returncode == 1 and run.stderr.strip().splitlines()[-1] == (
      "error: --sensor: unknown sensor 'vlp32'; known: vlp16, hdl32, hdl64, vls128, front120, "
      "os0_64")


def test_row_names_parse_into_keypoints_descriptor_estimator_and_verification():
  assert feature_store.split_row('auto+ours+upright+verify') == ('auto', 'ours')
  assert feature_store.row_estimator('auto+ours+upright+verify') == 'upright'
  assert feature_store.row_verifies('auto+ours+upright+verify')
  assert not feature_store.row_verifies('iss+fpfh') and feature_store.row_estimator('iss+fpfh') == 'rigid'
  assert feature_store.row_label('auto+fpfh+rigid+verify') == 'farthest-point kpt + FPFH desc, verified'
  assert feature_store.row_bev_candidates('auto+ours+upright+verify+bev') == 5
  assert feature_store.row_bev_candidates('auto+ours+upright+verify') == 0
  for bad in ('iss', 'iss+fpfh+affine', 'iss+fpfh+upright+check', 'iss++upright',
              'auto+fpfh+rigid+verify+bev', 'auto+fpfh+upright+bev'):
    with pytest.raises(ValueError, match='must be "keypoints\\+descriptor\\[\\+estimator'):
      feature_store.split_row(bad)


def test_a_tilted_set_is_its_upright_twin_with_unit_2_tilted(tmp_path):
  config = tiny_cross_sensor_config()
  config.cross_sensor.sensors = ('vlp16',)
  cross_sensor.generate(config, tmp_path / 'upright')
  config.cross_sensor.tilt = (10.0, 30.0)
  cross_sensor.generate(config, tmp_path / 'tilted')
  upright = registration_sets.read_registration_set(tmp_path / 'upright')
  tilted = registration_sets.read_registration_set(tmp_path / 'tilted')
  assert len(upright) == len(tilted) == 2
  for u, t in zip(upright, tilted):
    # The same standpoints and yaw; only unit 2's frame turned about its own origin.
    np.testing.assert_allclose(t.transform[:3, 3], u.transform[:3, 3], atol=1e-6)
    turn = u.transform[:3, :3].T @ t.transform[:3, :3]
    angle = np.degrees(np.arccos(np.clip((np.trace(turn) - 1) / 2, -1, 1)))
    assert 10.0 - 1e-6 <= angle <= 30.0 + 1e-6
    assert abs(turn[2, 2] - np.cos(np.radians(angle))) < 1e-6   # about a horizontal axis
  config.cross_sensor.tilt = (30.0, 10.0)
  with pytest.raises(dataset.SyntheticConfigError, match='cross_sensor.tilt'):
    cross_sensor.generate(config, tmp_path / 'bad')
