"""ssd_jax.infra.checkpoint: saving, keeping and restoring train states, and damaged
checkpoints named in one line (inference) or moved aside (training resume)."""

import logging
import os
import shutil
import subprocess
import sys

import chex
import jax
import jax.numpy as jnp
import ml_collections
import numpy as np
import pytest

from ssd_jax import inference, train
from ssd_jax.infra import checkpoint
from tests.conftest import shared_path

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_save_keep_and_restore_round_trip(tmp_path):
  config = ml_collections.ConfigDict({'model': {'radius': 3.0}, 'seed': 7})
  ckpt = checkpoint.Checkpointer(tmp_path / 'ck', every=2, keep=2)
  tree = {'w': jnp.arange(6.0).reshape(2, 3), 'step': jnp.int32(0)}
  saved = [s for s in range(1, 7) if ckpt.save(s, {**tree, 'step': jnp.int32(s)}, config)]
  assert saved == [2, 4, 6]
  assert not ckpt.save(6, tree, config, force=True)    # that step exists already
  ckpt.wait_until_finished()
  assert ckpt.all_steps() == [4, 6] and ckpt.latest_step() == 6
  state, stored = ckpt.restore(checkpoint.abstract_like(tree))
  assert int(state['step']) == 6 and stored == config.to_dict()
  np.testing.assert_array_equal(state['w'], tree['w'])
  assert int(ckpt.restore(None, step=4)[0]['step']) == 4
  assert ckpt.restore_config(4) == config.to_dict()
  with pytest.raises(FileNotFoundError, match=r'no checkpoint at step 2 .*\(kept: \[4, 6\]\)'):
    ckpt.restore(None, step=2)
  ckpt.close()
  with pytest.raises(FileNotFoundError, match='no checkpoint in'):
    checkpoint.Checkpointer(tmp_path / 'empty').restore(None)


def _damage(step_dir, kind):
  """Truncate one file of a checkpoint as a full disk or a killed copy would."""
  if kind == 'array':
    target = max((step_dir / 'state').rglob('ocdbt.process_0/d/*'), key=lambda p: p.stat().st_size)
  else:
    target = step_dir / {'metadata': 'state/_METADATA', 'config': 'config/metadata'}[kind]
  target.write_bytes(target.read_bytes()[:40])


@pytest.mark.real_data
@pytest.mark.multiprocess
@pytest.mark.slow
def test_damaged_newest_checkpoint_falls_back_or_is_named(tiny_config, tmp_path):
  tiny_config.data.path = str(shared_path('kitti_object_velodyne'))
  tiny_config.train.num_steps = 4
  train.train_and_evaluate(tiny_config, str(tmp_path / 'run'))
  tiny_config.train.num_steps = 6
  straight = train.train_and_evaluate(tiny_config, str(tmp_path / 'straight'))
  for kind in ('array', 'metadata', 'config'):
    run = tmp_path / kind
    shutil.copytree(tmp_path / 'run', run)
    _damage(run / 'checkpoints' / '4', kind)
    # Loading for inference names the damaged folder in one line; no fallback there.
    with pytest.raises(checkpoint.CheckpointError, match=r'checkpoints/4: damaged checkpoint') as e:
      inference.load(run)
    assert '\n' not in str(e.value)
    if kind == 'array':   # every array read fails alike; one line is printed, no traceback
      cloud = shared_path('kitti_object_velodyne', '000000.bin')
      out = subprocess.run(
          [sys.executable, '-m', 'experiments.register', f'--cloud1={cloud}', f'--cloud2={cloud}',
           '--descriptor=learned', f'--checkpoint={run}'],
          cwd=ROOT, capture_output=True, text=True, timeout=300)
      assert out.returncode != 0 and out.stderr.strip().count('\n') == 0, out.stderr[-2000:]
      assert 'checkpoints/4: damaged checkpoint' in out.stderr
    # Training moves it aside, resumes from step 2 and ends where a straight run ends.
    resumed = train.train_and_evaluate(tiny_config, str(run))
    assert sorted(os.listdir(run / 'checkpoints')) == ['2', '4', '4.damaged', '6']
    chex.assert_trees_all_equal(jax.device_get(resumed.params), jax.device_get(straight.params))
  # Nothing intact: one line, and the damaged folders are kept.
  run = tmp_path / 'all'
  shutil.copytree(tmp_path / 'run', run)
  for step in ('2', '4'):
    _damage(run / 'checkpoints' / step, 'array')
  with pytest.raises(checkpoint.CheckpointError, match='no intact checkpoint'):
    train.train_and_evaluate(tiny_config, str(run))
  assert sorted(os.listdir(run / 'checkpoints')) == ['2.damaged', '4.damaged']


def test_a_background_save_lost_to_a_dead_peer_logs_no_traceback():
  """orbax logs a traceback when a save's barrier fails because another process of the run
  is gone (`distributed` ends the run in one line); any other error of a save still logs."""
  def record(message, error):
    return logging.LogRecord('absl', logging.ERROR, 'async_checkpointer.py', 1, message, (),
                             (type(error), error, None))
  try:
    try:
      raise RuntimeError('UNAVAILABLE: Task 1 heartbeat timeout')
    except RuntimeError as cause:
      raise TimeoutError('Timed out while waiting for async_write_complete barrier') from cause
  except TimeoutError as e:
    lost = e
  failed = "[process=0] Failed to run 2 Handler Commit operations in background save thread"
  assert not checkpoint._drop_peer_failure_records(record(failed, lost))
  assert checkpoint._drop_peer_failure_records(record(failed, OSError('disk full')))
  assert checkpoint._drop_peer_failure_records(record('another error', lost))
