r"""Export a training run's checkpoint as a small pretrained model folder (weights and
BatchNorm statistics, no optimizer state, and the config), loadable by name or path.

    python -m experiments.export --run=runs/ours --out=ssd_jax/weights/ours [--step=12000] \
        [--num_samples=64 --draws=4]

A MODEL_CARD.md already in OUT is kept; write one (data, config, steps, wall time,
machine, command, results) for every model you share.
"""

from absl import app
from absl import flags

from ssd_jax import pretrained
from ssd_jax.infra import cli

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
  model = pretrained.export_run(FLAGS.run, FLAGS.out, FLAGS.step, FLAGS.num_samples,
                                FLAGS.draws)
  print(f'exported step {model.step} of {FLAGS.run} to {FLAGS.out}')


def console():
  """The `ssd-jax-export` command (pyproject.toml)."""
  cli.run(main)


if __name__ == '__main__':
  console()
