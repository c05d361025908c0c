"""Registration entry points on a tiny synthetic set: readers, register, evaluate."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from ssd_jax.data import benchmarks, io

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture
def tiny_set(synthetic_root):
  return synthetic_root


def _run(*args):
  return subprocess.run([sys.executable, '-m', *args], cwd=ROOT, capture_output=True, text=True,
                        timeout=600)


def test_readers_of_both_layouts(tiny_set):
  kitti = benchmarks.read_registration_set(tiny_set / 'test_kitti')
  single = benchmarks.read_registration_set(tiny_set / 'test_kitti' / '00')
  oxford = benchmarks.read_registration_set(tiny_set / 'test_oxford')
  assert len(kitti) == len(single) >= 5 and len(oxford) >= 5
  assert kitti[0].cloud1.name == f'{kitti[0].idx1:06d}.bin' and kitti[0].sequence == '00'
  assert oxford[0].cloud1.parent.name == 'test_models'
  with pytest.raises(io.CloudFileError, match='no groundtruths.txt here'):
    benchmarks.read_registration_set(tiny_set / 'train')


def test_register_cli_fpfh_on_a_synthetic_pair(tiny_set, tmp_path):
  folder = tiny_set / 'test_kitti' / '00'
  pair = benchmarks.read_registration_set(folder)[0]
  out = _run('experiments.register', f'--cloud1={pair.cloud1}', f'--cloud2={pair.cloud2}',
             f'--groundtruth={folder / "groundtruths.txt"}', f'--json={tmp_path / "r.json"}',
             f'--plot={tmp_path / "r.png"}', '--fpfh_max_nn=200')
  assert out.returncode == 0, out.stderr[-3000:]
  result = json.loads((tmp_path / 'r.json').read_text())
  t = np.array(result['T_12'])
  assert t.shape == (4, 4) and result['errors']['success'], result
  np.testing.assert_allclose(t[:3, 3], pair.transform[:3, 3], atol=1.0)
  assert result['inliers'] >= 3 and result['trials'] >= 10
  assert (tmp_path / 'r.png').stat().st_size > 10_000
  assert 'vs ground truth: RTE' in out.stdout


def test_register_cli_errors(tiny_set, tmp_path):
  cloud = tiny_set / 'test_kitti' / '00' / '000000.bin'
  out = _run('experiments.register', f'--cloud1={cloud}', f'--cloud2={tmp_path / "nope.bin"}')
  assert out.returncode != 0 and 'nope.bin: no such file' in out.stderr
  assert 'Traceback' not in out.stderr
  out = _run('experiments.register', f'--cloud1={cloud}', f'--cloud2={cloud}',
             '--descriptor=learned', f'--checkpoint={tmp_path / "none"}')
  assert out.returncode != 0 and 'none: no such checkpoint directory' in out.stderr
  assert 'Traceback' not in out.stderr


def test_register_cli_learned_uses_the_shipped_model(tiny_set, tmp_path):
  """No --checkpoint: the shipped `ours` model describes, and the pair registers."""
  folder = tiny_set / 'test_kitti' / '00'
  pair = benchmarks.read_registration_set(folder)[0]
  out = _run('experiments.register', f'--cloud1={pair.cloud1}', f'--cloud2={pair.cloud2}',
             '--descriptor=learned', f'--groundtruth={folder / "groundtruths.txt"}',
             f'--json={tmp_path / "r.json"}')
  assert out.returncode == 0, out.stderr[-3000:]
  result = json.loads((tmp_path / 'r.json').read_text())
  assert result['descriptor'] == 'learned' and result['model'] == 'ours'
  assert result['errors']['success'], result


def test_evaluate_registration_rows_and_missing_models(tiny_set, tmp_path):
  out = _run('experiments.evaluate_registration', f'--workdir={tmp_path}',
             f'--config.dataset={tiny_set / "test_kitti"}', '--config.max_pairs=3',
             "--config.rows=('iss+fpfh','iss+ours')", f'--config.checkpoints.ours={tmp_path / "x"}',
             '--config.fpfh_max_nn=200')
  assert out.returncode == 0, out.stderr[-3000:]
  md = (tmp_path / 'registration.md').read_text()
  assert '| ISS kpt + FPFH desc | 3 |' in md
  assert '| ISS kpt + Ours desc | missing |' in md and 'no such checkpoint directory' in md
  lines = [json.loads(l) for l in (tmp_path / 'registration_pairs.jsonl').read_text().splitlines()]
  assert len(lines) == 3 and all(l['row'] == 'iss+fpfh' for l in lines)
  assert (tmp_path / 'registration.csv').read_text().count('\n') == 3


@pytest.mark.parametrize('names,descriptor', [
    (('oxford_270', 'oxford_456'), 'learned'), (('kitti_00_001554', 'kitti_00_004534'), 'learned'),
    (('kitti_00_001554', 'kitti_00_004534'), 'fpfh')])
def test_register_cli_on_real_pairs(names, descriptor, tmp_path):
  """The real pairs have no ground truth: the RANSAC pose must be a success (RTE < 2 m,
  RRE < 5°) against the ICP-refined pose, and most points of cloud 2 must land on cloud 1.
  The learned rows use the shipped model."""
  from tests.conftest import shared_path  # pylint: disable=g-import-not-at-top
  c1, c2 = (shared_path('example', f'{n}.bin') for n in names)
  common = [f'--cloud1={c1}', f'--cloud2={c2}', f'--descriptor={descriptor}', '--fpfh_max_nn=200']
  out = _run('experiments.register', *common, f'--json={tmp_path / "ransac.json"}')
  assert out.returncode == 0, out.stderr[-3000:]
  out = _run('experiments.register', *common, '--icp', f'--json={tmp_path / "icp.json"}')
  assert out.returncode == 0, out.stderr[-3000:]
  ransac_t = np.array(json.loads((tmp_path / 'ransac.json').read_text())['T_12'])
  icp = json.loads((tmp_path / 'icp.json').read_text())
  from ssd_jax.registration import metrics  # pylint: disable=g-import-not-at-top
  err = metrics.registration_errors(np.array(icp['T_12']), ransac_t)
  assert icp['icp_fitness'] > 0.8 and icp['overlap_fitness'] > 0.7
  assert err['success'] and err['rte'] < 1.0, err
