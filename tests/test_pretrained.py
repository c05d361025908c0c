"""Exported and shipped pretrained models (ssd_jax.pretrained, experiments.export)."""

import os
import subprocess
import sys

import ml_collections
import numpy as np
import pytest

from ssd_jax import inference, pretrained, train
from ssd_jax.infra import checkpoint, errors
from tests.conftest import tiny_config_dict

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture(scope='module')
def tiny_run(tmp_path_factory):
  config = tiny_config_dict()
  config.model.orientation_head = 'equivariant'
  folder = tmp_path_factory.mktemp('clouds')
  rng = np.random.default_rng(0)
  for i in range(3):
    np.save(folder / f'{i}.npy', rng.uniform(-8, 8, (1200, 3)).astype(np.float32))
  config.data.path = str(folder)
  config.train.num_steps = 2
  workdir = tmp_path_factory.mktemp('run') / 'run'
  train.train_and_evaluate(config, str(workdir))
  return workdir


def _cloud():
  return np.random.default_rng(1).uniform(-8, 8, (1500, 3)).astype(np.float32)


@pytest.mark.multiprocess
@pytest.mark.slow
def test_export_loads_back_identical_and_small(tiny_run, tmp_path):
  out = tmp_path / 'export'
  run = subprocess.run([sys.executable, '-m', 'experiments.export', f'--run={tiny_run}',
                        f'--out={out}'], cwd=ROOT, capture_output=True, text=True, timeout=300)
  assert run.returncode == 0, run.stderr[-3000:]
  assert sorted(os.listdir(out)) == ['config.json', 'weights.msgpack']
  exported, original = pretrained.load(out), inference.load(tiny_run)
  assert exported.step == original.step == 2
  assert exported.net.orientation_head == 'equivariant'
  pts = _cloud()
  np.testing.assert_array_equal(inference.describe(exported, pts, pts[:30]),
                                inference.describe(original, pts, pts[:30]))
  # No optimizer state: the export is a third of the checkpoint's size.
  assert (out / 'weights.msgpack').stat().st_size < 600_000
  # The same loader takes a run directory and a step.
  assert pretrained.load(tiny_run, step=2).step == 2


def test_damaged_exports_are_named(tiny_run, tmp_path):
  out = pretrained.export(inference.load(tiny_run), _config_of(tiny_run), tmp_path / 'e')
  data = (out / 'weights.msgpack').read_bytes()
  (out / 'weights.msgpack').write_bytes(data[: len(data) // 2])
  with pytest.raises(ValueError, match='weights.msgpack: damaged'):
    pretrained.load(out)
  config = _config_of(tiny_run)
  config.inference.keypoints = 'ground'
  bad = pretrained.export(inference.load(tiny_run), config, tmp_path / 'bad_keypoints')
  with pytest.raises(errors.UserError, match="inference.keypoints must be one of .*got 'ground'"):
    pretrained.load(bad)
  (out / 'config.json').write_text('{"config": {"model": ')
  with pytest.raises(ValueError, match='config.json: not a readable model config'):
    pretrained.load(out)
  with pytest.raises(FileNotFoundError, match='no such checkpoint directory'):
    pretrained.load(tmp_path / 'nothing')


def _config_of(run):
  ckpt = checkpoint.Checkpointer(inference.checkpoint_directory(run), asynchronous=False)
  config = ml_collections.ConfigDict(ckpt.restore_config())
  ckpt.close()
  return config


@pytest.mark.parametrize('name', sorted(pretrained.SHIPPED))
def test_shipped_models_load_without_a_config_file_and_have_a_card(name):
  model = pretrained.load(name)
  card = (pretrained.WEIGHTS_DIR / name / 'MODEL_CARD.md').read_text()
  for needed in ('Command', 'Steps', 'Wall time', 'Machine', 'Data', 'Results'):
    assert needed in card, (name, needed)
  assert model.step is not None and str(model.step) in card
  pts = _cloud()
  desc = inference.describe(model, pts, pts[:16])
  assert desc.shape == (16, model.net.descriptor_dim) and np.all(np.isfinite(desc))
  np.testing.assert_allclose(np.linalg.norm(desc, axis=1), 1.0, atol=1e-4)


@pytest.mark.multiprocess
@pytest.mark.slow
def test_the_wheel_carries_every_shipped_model(tmp_path):
  """`pip install .` as a user does (a wheel, not editable): every folder of
  ssd_jax/weights/ is in it, and each model loads by name from another directory."""
  root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
  pip = [sys.executable, '-m', 'pip', '--disable-pip-version-check', '-q']
  built = subprocess.run(pip + ['wheel', '--no-deps', '-w', str(tmp_path / 'wheel'), root],
                         capture_output=True, text=True, timeout=600)
  assert built.returncode == 0, built.stderr[-3000:]
  wheel, = (tmp_path / 'wheel').glob('ssd_jax-*.whl')
  site = tmp_path / 'site'
  installed = subprocess.run(pip + ['install', '--no-deps', '--target', str(site), str(wheel)],
                             capture_output=True, text=True, timeout=600)
  assert installed.returncode == 0, installed.stderr[-3000:]
  assert sorted(p.name for p in (site / 'ssd_jax' / 'weights').iterdir()) == sorted(
      p.name for p in pretrained.WEIGHTS_DIR.iterdir()) == sorted(pretrained.SHIPPED)
  code = ('import ssd_jax; from ssd_jax import pretrained; '
          'print(ssd_jax.__file__); '
          'print(*[pretrained.load(n).step for n in sorted(pretrained.SHIPPED)])')
  run = subprocess.run([sys.executable, '-c', code], cwd=tmp_path, capture_output=True,
                       text=True, timeout=600, env={**os.environ, 'PYTHONPATH': str(site)})
  assert run.returncode == 0, run.stderr[-3000:]
  where, steps = run.stdout.splitlines()[-2:]
  assert where.startswith(str(site))
  assert [int(s) for s in steps.split()] == [pretrained.load(n).step
                                            for n in sorted(pretrained.SHIPPED)]
