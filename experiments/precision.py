r"""The precision test of paper Fig. 4 for every keypoint x descriptor row.

    python -m experiments.precision --config=configs/precision.py \
        --workdir=runs/precision_synthetic

Writes WORKDIR/precision.csv (one column per row, x = 0.1 ... 10 m),
precision.md (the value at x = 1 m and the keypoints counted) and precision.png.
"""

from absl import app
from absl import flags

from ssd_jax import cli
from ssd_jax.evaluation import runs
from ssd_jax.logging_utils import quiet_libraries

FLAGS = flags.FLAGS
flags.DEFINE_string('workdir', None, 'Output directory.')
cli.define_config_file('config', 'configs/precision.py', 'Evaluation config.')
flags.mark_flags_as_required(['workdir'])


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  quiet_libraries()
  config = FLAGS.config
  try:   # bad rows, missing, truncated or degenerate clouds: one line, no traceback
    store, missing = runs.open_store(config, config.rows)
    pairs = runs.load_pairs(config)
    print(runs.run_precision(config, pairs, store, missing, FLAGS.workdir,
                             f'{config.dataset} ({len(pairs)} pairs)'))
  except ValueError as e:
    raise SystemExit(f'error: {e}') from None


if __name__ == '__main__':
  cli.run(main)
