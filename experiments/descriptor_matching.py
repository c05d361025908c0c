r"""Descriptor matching (paper Table III): FPR at 95 % recall on cluster pairs.

    python -m experiments.descriptor_matching --config=configs/descriptor_matching.py \
        --workdir=runs/descriptor_matching_synthetic

Writes WORKDIR/descriptor_matching.md / .csv, descriptor_matching_roc.png and
distances.npz (per-pair labels, descriptor distances and ISS center distances).
"""

from absl import app
from absl import flags

from ssd_jax import cli
from ssd_jax.evaluation import runs
from ssd_jax.logging_utils import quiet_libraries

FLAGS = flags.FLAGS
flags.DEFINE_string('workdir', None, 'Output directory.')
cli.define_config_file('config', 'configs/descriptor_matching.py', 'Evaluation config.')
flags.mark_flags_as_required(['workdir'])


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  quiet_libraries()
  try:
    text = runs.run_descriptor_matching(FLAGS.config, FLAGS.config.clusters, FLAGS.workdir)
  except ValueError as e:   # missing, truncated or empty cluster files: one line
    raise SystemExit(f'error: {e}') from None
  print(text)


if __name__ == '__main__':
  cli.run(main)
