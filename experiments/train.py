r"""Train the self-supervised descriptor.

    python -m experiments.train --config=configs/training/paper_small.py --workdir=runs/small \
        --config.data.path=../shared/data/kitti_object_velodyne

Rerunning the same command resumes from the latest checkpoint in --workdir. The same
command runs over several processes (README, "Many machines"), e.g. two on one host:

    python -m experiments.train --config=configs/training/paper_small.py --workdir=runs/two \
        --coordinator_address=localhost:12355 --num_processes=2 --process_id=0 &
    python -m experiments.train --config=configs/training/paper_small.py --workdir=runs/two \
        --coordinator_address=localhost:12355 --num_processes=2 --process_id=1
"""

import os

from ssd_jax.infra import runtime

runtime.reexec_with_hugepages()

from absl import app  # pylint: disable=g-import-not-at-top,wrong-import-position
from absl import flags
from absl import logging
import jax

from ssd_jax import train
from ssd_jax.infra import cli, distributed
from ssd_jax.infra.logging_utils import quiet_libraries
from ssd_jax.data import io

FLAGS = flags.FLAGS
flags.DEFINE_string('workdir', None, 'Directory for checkpoints and metrics.jsonl.')
cli.define_config_file('config', None, 'Training config file.', lock_config=True)
cli.define_distributed_flags()
flags.mark_flags_as_required(['config', 'workdir'])


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  quiet_libraries()
  cli.initialize_distributed()
  logging.info('JAX devices: %s (process %d of %d)', jax.devices(), jax.process_index(),
               jax.process_count())
  try:
    train.train_and_evaluate(FLAGS.config, FLAGS.workdir)
  except io.CloudFileError as e:
    hint = ''
    if 'synthetic' in FLAGS.config.data.path and not os.path.exists(FLAGS.config.data.path):
      hint = ('\nthe synthetic set is made by: python -m experiments.data.make_synthetic '
              '--config=configs/data/synthetic_small.py --out=data_cache/synthetic_small')
    raise SystemExit(f'error: {e}{hint}') from None
  except Exception as e:  # pylint: disable=broad-except
    if not distributed.is_peer_failure(e):
      raise
    # A collective whose peer is gone (gloo: "Connection reset by peer"; NCCL alike), in
    # a step, an orbax save or a gather.
    distributed.fail(f'a step with the other processes failed ({str(e).splitlines()[0][:200]}): '
                     f'another process probably stopped; {distributed.STOPPED_HINT}')


def console():
  """The `ssd-jax-train` command (pyproject.toml)."""
  cli.run(main)


if __name__ == '__main__':
  console()
