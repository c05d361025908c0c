"""Pretrained models: small exported weights shipped with the package, and one loader
for every way a user names a model.

An export is a folder with three files:

    config.json      the training config (the network is rebuilt from its `model`)
    weights.msgpack  {'params', 'batch_stats'} (flax.serialization), no optimizer state
    MODEL_CARD.md    data, config, steps, wall time, machine, command, results

The shipped ones live in `ssd_jax/weights/<name>/` and are named by `SHIPPED`:

    model = pretrained.load(pretrained.DEFAULT)  # shipped: the register command's model
    model = pretrained.load('runs/ours')   # a training run (its latest checkpoint)
    model = pretrained.load('exports/mine')      # an export folder
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

import flax.serialization
import jax
import ml_collections
import numpy as np

from ssd_jax import inference, network
from ssd_jax.config_tools import upgrade
from ssd_jax.infra import errors

WEIGHTS_DIR = Path(__file__).resolve().parent / 'weights'
SHIPPED = {
    'ours': 'self-supervised descriptor (configs/training/ours.py)',
    'ours_detector': 'self-supervised descriptor and detector (configs/training/ours_detector.py)',
    'feat3dnet': 'weakly supervised 3DFeat-Net baseline (configs/training/feat3dnet.py)',
    'ours_rescan': 'ours fine-tuned to match across sensors and standpoints '
                   '(configs/training/ours_rescan.py)',
    'ours_mined': 'ours fine-tuned on pairs mined from a mixed-sensor drive '
                  '(configs/training/ours_mined.py)',
}
# The model the register command describes with, the evaluation's command rows name and
# `experiments.adapt` starts from, unless told otherwise: of the shipped self-supervised
# models, the one whose register defaults register the most real-drive pairs
# (docs/notes/real_drives.md); trained without a label on the project's own simulated drive.
DEFAULT = 'ours_mined'
CONFIG_FILE, WEIGHTS_FILE, CARD_FILE = 'config.json', 'weights.msgpack', 'MODEL_CARD.md'


def is_export(path: str | os.PathLike) -> bool:
  return (Path(path) / CONFIG_FILE).is_file() and (Path(path) / WEIGHTS_FILE).is_file()


def export(model: inference.Model, config: ml_collections.ConfigDict,
           out: str | os.PathLike, card: str = '') -> Path:
  """Write `model` (weights and BatchNorm statistics) and its config to folder `out`."""
  out = Path(out)
  out.mkdir(parents=True, exist_ok=True)
  record = {'config': config.to_dict(), 'step': model.step}
  (out / CONFIG_FILE).write_text(json.dumps(record, indent=1, default=list) + '\n')
  (out / WEIGHTS_FILE).write_bytes(flax.serialization.to_bytes(
      {'params': model.variables['params'], 'batch_stats': model.variables['batch_stats']}))
  if card:
    (out / CARD_FILE).write_text(card)
  return out


def load_export(path: str | os.PathLike) -> inference.Model:
  """An export folder -> `inference.Model`, or a clear error for a damaged one."""
  path = Path(path)
  try:
    record = json.loads((path / CONFIG_FILE).read_text())
    config = upgrade.upgrade(record['config'])
    template = network.variables_template(config.model)
  except (OSError, ValueError, KeyError, AttributeError) as e:
    raise errors.UserError(f'{path / CONFIG_FILE}: not a readable model config ({e})') from None
  # A numpy template: jnp.zeros would compile one fill kernel per weight shape.
  template = jax.tree.map(lambda s: np.zeros(s.shape, s.dtype), template)
  try:
    variables = jax.device_put(
        flax.serialization.from_bytes(template, (path / WEIGHTS_FILE).read_bytes()))
  except Exception as e:  # pylint: disable=broad-except  (msgpack raises many kinds)
    raise errors.UserError(f'{path / WEIGHTS_FILE}: damaged or not weights of this network '
                           f'({type(e).__name__}: {e})') from None
  model = inference.Model.from_config(config, variables)
  return dataclasses.replace(model, step=record.get('step'))


def export_run(run: str | os.PathLike, out: str | os.PathLike, step: int | None = None,
               num_samples: int = 0, draws: int = 0, card: str = '',
               keypoints: str = '') -> inference.Model:
  """Export checkpoint `step` (default: the latest) of training run `run` to folder `out`,
  optionally describing with `num_samples` points x `draws` samplings of each ball and
  'auto' keypoints from the `keypoints` domain (0 / '': the run's own setting), and check
  that it loads back. -> the exported model."""
  # Orbax only here and in training: loading a shipped or exported model never imports it.
  from ssd_jax.infra import checkpoint  # pylint: disable=g-import-not-at-top
  model = inference.load(run, step)
  ckpt = checkpoint.Checkpointer(inference.checkpoint_directory(run), asynchronous=False)
  config = upgrade.upgrade(ckpt.restore_config(model.step))
  ckpt.close()
  config.inference.num_samples = num_samples or config.inference.num_samples
  config.inference.draws = draws or config.inference.draws
  config.inference.keypoints = keypoints or config.inference.keypoints
  model = dataclasses.replace(inference.Model.from_config(config, model.variables),
                              step=model.step)
  load_export(export(model, config, out, card))   # what was written loads back
  return model


def resolve(name_or_path: str | os.PathLike) -> str:
  """A shipped name -> its folder; anything else is returned unchanged."""
  return str(WEIGHTS_DIR / name_or_path) if str(name_or_path) in SHIPPED else str(name_or_path)


def load(name_or_path: str | os.PathLike, step: int | None = None) -> inference.Model:
  """A shipped name (`SHIPPED`), an export folder or a training run -> `inference.Model`."""
  path = resolve(name_or_path)
  if str(name_or_path) in SHIPPED and not is_export(path):
    raise FileNotFoundError(f'the shipped model {name_or_path!r} is not in {path}')
  if is_export(path):
    if step is not None:
      raise errors.UserError(f'{path} is an export of one step; --step applies to training runs')
    return load_export(path)
  return inference.load(path, step)

