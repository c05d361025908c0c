r"""Adapt a trained descriptor to your own sensor without labels: fine-tune it on a folder
of unlabeled scans, then export it with a model card.

    python -m experiments.adapt --scans=/data/my_scans --out=exports/my_sensor \
        [--init=ours] [--steps=1500] [--config=configs/adapt.py]
    python -m experiments.register --cloud1=A.bin --cloud2=B.bin --descriptor=learned \
        --checkpoint=exports/my_sensor

The scans (.bin/.npy/.ply/.pcd/.las/.laz, one sweep each, centred on the sensor, z up)
train the self-supervised objective of the paper, which needs no poses. OUT/run holds
the training run (rerun the command to resume it); OUT holds the exported model
(config.json, weights.msgpack) and MODEL_CARD.md (base model, scans, steps, wall time,
machine, command). Under 10 minutes on 2 CPU cores at the default
1,500 steps (docs/notes/benchmarks.md).
"""

import datetime
import os
import platform
import sys
import time

from absl import app
from absl import flags

from ssd_jax import cli, pretrained, train
from ssd_jax.data import io
from ssd_jax.logging_utils import quiet_libraries

FLAGS = flags.FLAGS
flags.DEFINE_string('scans', None, 'Folder (or index .txt) of unlabeled scans of the sensor.')
flags.DEFINE_string('out', None, 'Output folder: the exported model, its card, and run/.')
flags.DEFINE_string('init', 'ours', 'Model to start from: a shipped name, export or run.')
flags.DEFINE_integer('steps', None, 'Training steps (default: the config\'s).')
cli.define_config_file('config', 'configs/adapt.py', 'Adaptation config.')
flags.mark_flags_as_required(['scans', 'out'])

CARD = """# {name}: `{init}` adapted to the scans of {scans}

Fine-tuned without labels (the paper's self-supervision: each scan against a turned,
re-sampled copy of itself) from `{init}`, every weight, on {num_scans} unlabeled scans.

| | |
|---|---|
| base model | `{init}` |
| scans | `{scans}` ({num_scans} files) |
| config | `configs/adapt.py` ({steps} steps, learning rate {lr:g}, {schedule}) |
| wall time | {minutes:.1f} minutes |
| machine | {machine} |
| written | {date} |

Command:

    {command}

Use it: `--checkpoint={out}` (register, evaluate, learning_curve) or
`pretrained.load('{out}')`.
"""


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  quiet_libraries()
  config = FLAGS.config
  config.data.path, config.train.init_from = FLAGS.scans, FLAGS.init
  if FLAGS.steps is not None:
    config.train.num_steps = FLAGS.steps
  run_dir = os.path.join(FLAGS.out, 'run')
  try:
    num_scans = len(io.list_clouds(FLAGS.scans))
    start = time.perf_counter()
    train.train_and_evaluate(config, run_dir)
    minutes = (time.perf_counter() - start) / 60
    card = CARD.format(
        name=os.path.basename(os.path.normpath(FLAGS.out)), init=FLAGS.init, scans=FLAGS.scans,
        num_scans=num_scans, steps=config.train.num_steps, lr=config.train.learning_rate,
        schedule=config.train.lr_schedule, minutes=minutes,
        machine=', '.join(filter(None, (platform.machine(), platform.processor(),
                                        f'{os.cpu_count()} cores', platform.system()))),
        date=datetime.date.today().isoformat(), command=' '.join(['python -m experiments.adapt']
                                                                  + sys.argv[1:]),
        out=FLAGS.out)
    model = pretrained.export_run(run_dir, FLAGS.out, card=card)
  except io.CloudFileError as e:
    raise SystemExit(f'error: --scans: {e}') from None
  print(f'wrote {FLAGS.out}: {FLAGS.init} adapted on {num_scans} scans of {FLAGS.scans} '
        f'({model.step} steps, {minutes:.1f} min); use it with --checkpoint={FLAGS.out}')


def console():
  """The `ssd-jax-adapt` command (pyproject.toml)."""
  cli.run(main)


if __name__ == '__main__':
  console()
