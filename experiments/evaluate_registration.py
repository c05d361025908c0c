r"""The registration tables (paper Tables I / II) for keypoint x descriptor rows.

    python -m experiments.evaluate_registration --config=configs/registration.py \
        --workdir=runs/registration_synthetic

Writes WORKDIR/registration.md, registration.csv and registration_pairs.jsonl
(one line per pair and row: RTE, RRE (Euler sum and geodesic), success, trials,
inliers).
"""

from absl import app
from absl import flags

from ssd_jax import cli
from ssd_jax.evaluation import runs
from ssd_jax.logging_utils import quiet_libraries

FLAGS = flags.FLAGS
flags.DEFINE_string('workdir', None, 'Output directory.')
cli.define_config_file('config', 'configs/registration.py', 'Evaluation config.')
flags.mark_flags_as_required(['workdir'])


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  quiet_libraries()
  config = FLAGS.config
  try:   # bad rows, missing, truncated or degenerate clouds: one line, no traceback
    store, missing = runs.open_store(config, config.rows)
    pairs = runs.load_pairs(config)
    print(runs.run_registration(config, pairs, store, missing, FLAGS.workdir, config.paper,
                                f'{config.dataset} ({len(pairs)} pairs)'))
  except ValueError as e:
    raise SystemExit(f'error: {e}') from None


if __name__ == '__main__':
  cli.run(main)
