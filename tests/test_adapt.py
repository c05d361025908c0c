"""Label-free adaptation (experiments.adapt): fine-tune the shipped model on a folder of
unlabeled scans, export it with its card, register with it."""

import os
import subprocess
import sys

import jax
import numpy as np
import pytest

from ssd_jax import pretrained
from ssd_jax.data import io, mined_pairs, registration_sets
from ssd_jax.registration import metrics, pipeline
from ssd_jax.synthetic import cross_sensor
from tests.conftest import tiny_cross_sensor_config

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
  assert f'wrote {out}: ours adapted on' in run.stdout
  card = (out / 'MODEL_CARD.md').read_text()
  assert '| base model | `ours` |' in card and '2 steps' in card and 'experiments.adapt' in card
  # The drive's pairs were mined first and trained on.
  kept = mined_pairs.read_kept(str(out / 'mined_pairs.csv'))
  assert f'| mined pairs | {len(kept)} (`{out / "mined_pairs.csv"}`) |' in card
  assert 'two-view training' in card
  adapted, ours = pretrained.load(str(out)), pretrained.load('ours')
  assert adapted.step == 2
  # Every weight starts from ours (init_scope 'model'), the detector's too, and moved a little.
  moved = jax.tree.map(lambda a, b: float(np.abs(np.asarray(a) - np.asarray(b)).max()),
                       adapted.variables['params'], ours.variables['params'])
  assert 0 < max(jax.tree.leaves(moved)) < 0.05
  pair = registration_sets.read_registration_set(synthetic_root / 'test_kitti')[0]
  reg, _, _ = pipeline.register(target=io.read_cloud(pair.cloud1),
                                source=io.read_cloud(pair.cloud2), model=adapted,
                                options=pipeline.Options.paper('learned'))
  assert metrics.registration_errors(pair.transform, reg.transform)['success']


@pytest.mark.multiprocess
def test_adapt_refuses_a_missing_folder(tmp_path):
  run = subprocess.run([sys.executable, '-m', 'experiments.adapt', f'--scans={tmp_path / "no"}',
                        f'--out={tmp_path / "o"}'], cwd=ROOT, capture_output=True, text=True,
                       timeout=120)
  assert run.returncode == 1 and run.stderr.strip().splitlines()[-1].startswith(
      'error: --scans:'), run.stderr[-2000:]
