r"""Run the evaluations a config names (`config.evals`) and write their report.

    python -m experiments.evaluate --config=configs/evals/registration.py --workdir=runs/reg
    python -m experiments.evaluate --config=configs/evals/reproduce.py \
        --config.data_root=DIR --workdir=OUT

configs/evals/registration.py (Tables I / II), precision.py (Fig. 4), repeatability.py,
descriptor_matching.py (Table III) name one evaluation each; reproduce.py names every
table and figure of the paper (ssd_jax/evaluation/evaluators.py describes the types).
Writes each evaluation's tables and figures into WORKDIR under its name, and
WORKDIR/report.md. With --coordinator_address / --num_processes / --process_id (or a
Slurm, Open MPI or Cloud TPU launcher) the same command runs over several processes:
each evaluation splits its pairs over them, and process 0 writes the one report.
"""

import shlex
import sys

from absl import app
from absl import flags

from ssd_jax.infra import cli, distributed, errors
from ssd_jax.evaluation import evaluators
from ssd_jax.infra.logging_utils import quiet_libraries

FLAGS = flags.FLAGS
flags.DEFINE_string('workdir', None, 'Output directory.')
cli.define_config_file('config', 'configs/evals/registration.py', 'Evaluation config.')
cli.define_distributed_flags()
flags.mark_flags_as_required(['workdir'])


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  quiet_libraries()
  cli.initialize_distributed()
  command = 'python -m experiments.evaluate ' + shlex.join(sys.argv[1:])
  try:
    path, text = evaluators.evaluate(FLAGS.config, FLAGS.workdir, command)
  except Exception as e:  # pylint: disable=broad-except
    if distributed.is_peer_failure(e):   # first: a collective may raise it as a ValueError
      distributed.fail(f'gathering results from the other processes failed '
                       f'({str(e).splitlines()[0][:200]}): another process probably stopped')
    if isinstance(e, errors.UserError):   # bad rows or types, missing or damaged data
      raise SystemExit(f'error: {e}') from None
    raise
  if distributed.is_main():
    print(text)
    print(f'\nwrote {path}')


def console():
  """The `ssd-jax-evaluate` command (pyproject.toml)."""
  cli.run(main)


if __name__ == '__main__':
  console()
