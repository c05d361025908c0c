r"""Export a training run's checkpoint as a small pretrained model folder (weights and
BatchNorm statistics, no optimizer state, and the config), loadable by name or path.

    python -m experiments.export --run=runs/cpu_robust --out=ssd_jax/weights/ours [--step=12000] \
        [--num_samples=64 --draws=4]

A MODEL_CARD.md already in OUT is kept; write one (data, config, steps, wall time,
machine, command, results) for every model you share.
"""

import dataclasses

from absl import app
from absl import flags
import ml_collections

from ssd_jax import checkpoint, cli, inference, pretrained

FLAGS = flags.FLAGS
flags.DEFINE_string('run', None, 'Training workdir.')
flags.DEFINE_string('out', None, 'Export folder.')
flags.DEFINE_integer('step', None, 'Checkpoint step (default: the latest).')
flags.DEFINE_integer('num_samples', 0, 'Set config.inference.num_samples (0: keep the run\'s).')
flags.DEFINE_integer('draws', 0, 'Set config.inference.draws (0: keep the run\'s).')
flags.mark_flags_as_required(['run', 'out'])


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  try:
    model = inference.load(FLAGS.run, FLAGS.step)
    ckpt = checkpoint.Checkpointer(inference.checkpoint_directory(FLAGS.run), asynchronous=False)
    config = ml_collections.ConfigDict(ckpt.restore_config(model.step))
    ckpt.close()
    if 'inference' not in config:   # runs from before the section describe as they trained
      config.inference = ml_collections.ConfigDict({'num_samples': 0, 'draws': 1})
    config.inference.num_samples = FLAGS.num_samples or config.inference.num_samples
    config.inference.draws = FLAGS.draws or config.inference.draws
    model = dataclasses.replace(inference.Model.from_config(config, model.variables),
                                step=model.step)
    out = pretrained.export(model, config, FLAGS.out)
    pretrained.load_export(out)   # what was written loads back
  except (FileNotFoundError, ValueError) as e:
    raise SystemExit(f'error: {e}') from None
  print(f'exported step {model.step} of {FLAGS.run} to {out}')


def console():
  """The `ssd-jax-export` command (pyproject.toml)."""
  cli.run(main)


if __name__ == '__main__':
  console()
