r"""Keypoint repeatability of each keypoint source on a registration test set.

    python -m experiments.repeatability --config=configs/repeatability.py \
        --workdir=runs/repeatability_synthetic

Writes WORKDIR/repeatability.md and .csv.
"""

from absl import app
from absl import flags

from ssd_jax import cli
from ssd_jax.evaluation import runs
from ssd_jax.logging_utils import quiet_libraries

FLAGS = flags.FLAGS
flags.DEFINE_string('workdir', None, 'Output directory.')
cli.define_config_file('config', 'configs/repeatability.py', 'Evaluation config.')
flags.mark_flags_as_required(['workdir'])


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  quiet_libraries()
  config = FLAGS.config
  try:   # bad names, missing, truncated or degenerate clouds: one line, no traceback
    store, missing = runs.open_store(config, [f'{s}+fpfh' for s in config.keypoint_sources])
    pairs = runs.load_pairs(config)
    print(runs.run_repeatability(config, pairs, store, missing, FLAGS.workdir,
                                 f'{config.dataset} ({len(pairs)} pairs)'))
  except ValueError as e:
    raise SystemExit(f'error: {e}') from None


if __name__ == '__main__':
  cli.run(main)
