"""experiments.benchmarks: the train-step benchmark measures a real step of a config; the
registration benchmark sets the register command beside its anchors in every regime."""

import json
import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.multiprocess
@pytest.mark.slow
def test_train_step_benchmark_times_a_compiled_step():
  """One config's row, as the parent process collects it: a positive step time and the
  analytic FLOP count of `forward_flops` (3 x forward), beside XLA's own count."""
  out = subprocess.run([sys.executable, '-m', 'experiments.benchmarks.training',
                        '--child=paper_small', '--steps=1', '--breakdown=false'],
                       cwd=ROOT, capture_output=True, text=True, timeout=600)
  assert out.returncode == 0, out.stderr[-3000:]
  row = json.loads([l for l in out.stdout.splitlines() if l.startswith('RESULT ')][-1][7:])
  assert row['config'] == 'paper_small' and row['batch'] == 2 and row['points'] == 2048
  assert 0 < row['step_s'] < 60 and row['compile_s'] > 0
  # 2 x 2 clouds x 256 clusters x 32 points through the dense layers, three times over.
  assert abs(row['train_gflop'] - 12.0) < 0.1
  assert 0.8 < row['xla_gflop'] / row['train_gflop'] < 1.2


@pytest.mark.multiprocess
@pytest.mark.slow
def test_registration_benchmark_sets_the_command_beside_an_anchor_in_every_regime(
    synthetic_root):
  """The table: the register command's batch rows (per pair from its CSV, and the whole
  command), Open3D's pipeline on the same pairs and the ratio of the two medians, warm and
  cold rows, a loop-closure list of every pair of 3 scans, a pair densified to 100,000
  points per cloud (put on the grid by the command, with that run's own peak memory), a
  pair of 25-scan tiles of 50,000 points, and the seconds of each stage."""
  dataset = str(synthetic_root / 'test_kitti')
  out = subprocess.run([sys.executable, '-m', 'experiments.benchmarks.registration',
                        f'--datasets={dataset}', '--num_pairs=2', '--cold_pairs=1',
                        '--loop_scans=3', '--methods=register,open3d', '--dense=100000',
                        '--tile=50000'], cwd=ROOT, capture_output=True, text=True, timeout=900)
  assert out.returncode == 0, out.stderr[-3000:]
  rows = [[c.strip() for c in l.strip().strip('|').split('|')]
          for l in out.stdout.splitlines() if l.startswith('| ')]
  batch = [r for r in rows if r[2] == 'batch (`--pairs`), in its CSV'][0]
  anchor = [r for r in rows if r[0] == dataset and r[1].startswith('Open3D')][0]
  assert batch[3] == anchor[3] == '2' and batch[6] == '100.0 %', batch
  assert float(batch[8]) == pytest.approx(float(batch[4]) / float(anchor[4]), abs=0.01)
  regimes = [r[2].split(':')[0] for r in rows if r[1].startswith('register')]
  assert {'warm', 'cold'} <= set(regimes), regimes
  assert any(r[0] == 'loop closure: every pair of 3 scans' and r[3] == '3' for r in rows)
  dense = [r for r in rows if r[0] == '100,000 points per cloud'][0]
  tile = [r for r in rows if r[0] == '50,000-point tile per cloud'][0]
  assert dense[6] == tile[6] == '100.0 %', (dense, tile)
  assert 0.1 < float(dense[2].split('peak ')[1].split(' GiB')[0]) < 2.0
  stages = [r for r in rows if r[0] == dataset and r[1][:1].isdigit()]
  assert stages and all(float(v) >= 0 for v in stages[0][1:]), stages


@pytest.mark.multiprocess
def test_registration_benchmark_refuses_a_negative_size_in_one_line(synthetic_root):
  out = subprocess.run([sys.executable, '-m', 'experiments.benchmarks.registration',
                        f'--datasets={synthetic_root / "test_kitti"}', '--tile=-5'],
                       cwd=ROOT, capture_output=True, text=True, timeout=300)
  assert out.returncode != 0 and out.stderr.strip() == (
      'error: --num_pairs, --cold_pairs, --loop_scans, --dense, --tile must be >= 0, got '
      '0, 3, 12, 0, -5')
