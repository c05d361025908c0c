"""One run over several processes (`ssd_jax.infra.distributed`): 2 local CPU processes against
1, through the commands a user runs."""

import json
import os
import signal
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

from ssd_jax.infra import distributed

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

TINY_TRAIN = ['--config=configs/training/paper_small.py', '--config.data.num_points=512',
              '--config.model.num_clusters=64', '--config.model.num_samples=16',
              '--config.train.batch_size=2', '--config.train.log_every=1',
              '--config.train.eval_every=2', '--config.train.checkpoint_every=2',
              '--config.progress_bar=False', '--config.data.eval_path=']


def _free_port() -> int:
  with socket.socket() as s:
    s.bind(('localhost', 0))
    return s.getsockname()[1]


def _env(devices: int) -> dict:
  return dict(os.environ, JAX_PLATFORMS='cpu',
              XLA_FLAGS=f'--xla_force_host_platform_device_count={devices}')


def _start(module: str, args, processes: int = 1, devices: int = 1, timeout_s: int = 60,
           **kwargs) -> list[subprocess.Popen]:
  """`python -m module args` as `processes` processes of one run (1: a plain run)."""
  extra = [[]]
  if processes > 1:
    port = _free_port()
    extra = [[f'--coordinator_address=localhost:{port}', f'--num_processes={processes}',
              f'--process_id={p}', f'--distributed_timeout={timeout_s}']
             for p in range(processes)]
  return [subprocess.Popen([sys.executable, '-m', module, *args, *e], cwd=ROOT,
                           env=_env(devices), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           text=True, **kwargs) for e in extra]


def _finish(procs, timeout=600) -> list[tuple[int, str]]:
  out = []
  for p in procs:
    stdout, stderr = p.communicate(timeout=timeout)
    out.append((p.returncode, stdout + stderr))
  return out


def _run(module, args, **kwargs):
  results = _finish(_start(module, args, **kwargs))
  for code, text in results:
    assert code == 0, text[-3000:]
  return results


def _losses(workdir) -> dict[int, float]:
  with open(os.path.join(workdir, 'metrics.jsonl')) as f:
    return {r['step']: r['loss'] for r in map(json.loads, f) if 'loss' in r}


def test_helpers_in_one_process():
  assert not distributed.environment_has_many({})
  assert not distributed.environment_has_many({'SLURM_NTASKS': '4'})   # an allocation, no step
  assert distributed.environment_has_many({'SLURM_NTASKS': '4', 'SLURM_STEP_ID': '0'})
  assert not distributed.environment_has_many({'SLURM_NTASKS': '1', 'SLURM_STEP_ID': '0'})
  assert distributed.environment_has_many({'OMPI_COMM_WORLD_SIZE': '2'})
  assert distributed.environment_has_many({'TPU_WORKER_HOSTNAMES': 'a,b'})
  assert not distributed.environment_has_many({'TPU_WORKER_HOSTNAMES': 'a'})
  assert distributed.environment_has_many({'JAX_COORDINATOR_ADDRESS': 'host:1234'})
  assert distributed.local_rows(6) == range(6)
  assert distributed.gather({'a': 1}) == [{'a': 1}]
  seen = []
  assert distributed.map_items(lambda n, x: (n, x * x), [3, 4, 5],
                               lambda ns: seen.extend(ns) or ns) == [(0, 9), (1, 16), (2, 25)]
  assert seen == [0, 1, 2]


@pytest.mark.slow
def test_two_processes_train_like_one_and_share_checkpoints(synthetic_root, tmp_path):
  one, two = tmp_path / 'one', tmp_path / 'two'

  def train(workdir, steps, **layout):
    return _run('experiments.train', TINY_TRAIN + [f'--config.data.path={synthetic_root / "train"}',
                                                   f'--config.train.num_steps={steps}',
                                                   f'--workdir={workdir}'], **layout)

  # One process with 2 devices and two processes with 1 each: the same mesh of 2.
  train(one, 4, devices=2)
  logs = train(two, 4, processes=2)
  assert 'process 1 of 2' in logs[1][1]
  l1, l2 = _losses(one), _losses(two)
  assert sorted(l1) == [1, 2, 3, 4] and sorted(l2) == [1, 2, 3, 4]   # written once
  np.testing.assert_allclose([l2[s] for s in l2], [l1[s] for s in l2], rtol=1e-6)
  assert len(set(l1.values())) == 4
  # Each run's checkpoint at step 4 continues in the other layout, to the same losses.
  train(two, 6, devices=2)
  logs = train(one, 6, processes=2)
  assert 'Resumed from step 4' in logs[0][1]
  l1, l2 = _losses(one), _losses(two)
  assert sorted(l1) == sorted(l2) == [1, 2, 3, 4, 5, 6]
  np.testing.assert_allclose([l2[s] for s in (5, 6)], [l1[s] for s in (5, 6)], rtol=1e-6)


@pytest.mark.slow
def test_evaluation_split_over_two_processes_writes_the_same_table(synthetic_root, tmp_path):
  args = ['--config=configs/evals/registration.py', f'--config.data_root={synthetic_root}',
          '--config.evals.registration.dataset=test_kitti', '--config.max_pairs=3',
          "--config.rows=('iss+fpfh','iss+ours')", '--config.fpfh_max_nn=200']
  _run('experiments.evaluate', args + [f'--workdir={tmp_path / "one"}'])
  logs = _run('experiments.evaluate', args + [f'--workdir={tmp_path / "two"}'], processes=2)
  assert 'wrote' in logs[0][1] and 'wrote' not in logs[1][1]   # process 0 reports
  for name in ('registration.csv', 'registration_pairs.jsonl'):
    assert (tmp_path / 'one' / name).read_text() == (tmp_path / 'two' / name).read_text(), name
  fingerprints = lambda p: [l for l in (p / 'report.md').read_text().splitlines() if '`' in l
                            and ('keypoints:' in l or 'descriptors:' in l or 'clouds' in l
                                 or 'registration:' in l)]
  assert len(fingerprints(tmp_path / 'one')) >= 5
  assert fingerprints(tmp_path / 'one') == fingerprints(tmp_path / 'two')
  assert not list((tmp_path / 'two').glob('*process*'))


def _one_error_line(text: str) -> str:
  for bad in ('Traceback', 'Check failure', 'Fatal Python error', '    @ 0x'):
    assert bad not in text, text[-3000:]
  errors = [l for l in text.splitlines() if l.startswith('error: ')]
  assert len(errors) == 1, text[-3000:]
  return errors[0]


@pytest.mark.multiprocess
@pytest.mark.slow
def test_a_process_that_never_joins_ends_the_run_in_one_line(synthetic_root, tmp_path):
  port = _free_port()
  t0 = time.monotonic()
  proc = subprocess.run(
      [sys.executable, '-m', 'experiments.train', *TINY_TRAIN, f'--workdir={tmp_path}',
       f'--config.data.path={synthetic_root / "train"}', f'--coordinator_address=localhost:{port}',
       '--num_processes=2', '--process_id=0', '--distributed_timeout=3'],
      cwd=ROOT, env=_env(1), capture_output=True, text=True, timeout=300)
  assert proc.returncode == 1
  assert 'not all 2 processes joined the coordinator' in _one_error_line(proc.stderr)
  assert time.monotonic() - t0 < 120


@pytest.mark.multiprocess
@pytest.mark.parametrize('args, message', [
    (['--num_processes=2', '--process_id=2'], '--process_id=2: must be in [0, 2)'),
    (['--num_processes=0'], '--num_processes=0: must be at least 1'),
])
def test_wrong_process_settings_are_one_line(args, message, tmp_path):
  proc = subprocess.run([sys.executable, '-m', 'experiments.train', *TINY_TRAIN,
                         f'--workdir={tmp_path}', '--coordinator_address=localhost:1', *args],
                        cwd=ROOT, env=_env(1), capture_output=True, text=True, timeout=300)
  assert proc.returncode == 2
  assert _one_error_line(proc.stderr) == f'error: {message}'


@pytest.mark.multiprocess
@pytest.mark.slow
def test_a_killed_process_stops_the_run_and_the_rerun_resumes(synthetic_root, tmp_path):
  args = TINY_TRAIN + [f'--config.data.path={synthetic_root / "train"}', f'--workdir={tmp_path}']
  # New sessions: killing process 1's group kills the command and its worker at once.
  procs = _start('experiments.train', args + ['--config.train.num_steps=100000'], processes=2,
                 timeout_s=15, start_new_session=True)
  deadline = time.monotonic() + 300
  while not (tmp_path / 'checkpoints' / '4').exists():
    assert time.monotonic() < deadline and procs[0].poll() is None, _finish(procs)
    time.sleep(0.5)
  os.killpg(procs[1].pid, signal.SIGKILL)
  t0 = time.monotonic()
  (code, text), _ = _finish(procs, timeout=120)
  assert code == 1 and time.monotonic() - t0 < 60
  assert 'another process' in _one_error_line(text)
  # Rerun both: they resume from the last checkpoint and finish.
  logs = _run('experiments.train', args + ['--config.train.num_steps=8'], processes=2)
  assert all('Resumed from step' in text for _, text in logs)
  assert max(_losses(tmp_path)) == 8
