r"""Does a checkpoint hold over the whole circle? Turn a cloud about z in steps and
compare every cluster with its turned self (orientation error, descriptor distance,
self-match rate), for one or more checkpoints.

    python -m experiments.diagnostics.rotation_sweep --checkpoint=ours=runs/ours \
        --checkpoint=paper=runs/paper_small --cloud=../shared/data/example/oxford_270.bin \
        --out=runs/rotation_sweep
"""

import os

from absl import app
from absl import flags
import numpy as np

from ssd_jax import pretrained, viz
from ssd_jax.infra import cli
from ssd_jax.data import clean, io
from ssd_jax.evaluation import orientation, tables
from ssd_jax.infra.logging_utils import quiet_libraries

FLAGS = flags.FLAGS
flags.DEFINE_multi_string('checkpoint', None, 'NAME=MODEL: a shipped name, run or export '
                          'folder (repeatable).')
flags.DEFINE_string('cloud', None, 'A cloud file (any format the project reads).')
flags.DEFINE_string('out', None, 'Write rotation_sweep.csv/.md/.png here.')
flags.DEFINE_integer('num_centers', 256, 'Random cluster centers (seeded).')
flags.DEFINE_integer('step_deg', 15, 'Angle step, degrees.')
flags.DEFINE_integer('seed', 0, 'Seed of the centers.')
flags.mark_flags_as_required(['checkpoint', 'cloud'])

HEADER = ('checkpoint', 'angle (°)', 'orientation error (°)', 'descriptor distance',
          'self-match rate (%)')


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  quiet_libraries()
  points = clean.clean_cloud(io.read_cloud(FLAGS.cloud), FLAGS.cloud)
  rng = np.random.default_rng(FLAGS.seed)
  centers = points[rng.choice(len(points), min(FLAGS.num_centers, len(points)), replace=False)]
  angles = list(range(0, 360, FLAGS.step_deg))
  sweeps = {}
  for spec in FLAGS.checkpoint:
    name, sep, path = spec.partition('=')
    if not sep:
      raise ValueError(f'--checkpoint {spec!r} must be NAME=RUN_DIR')
    sweeps[name] = orientation.rotation_sweep(pretrained.load(path), points, centers, angles)
  rows = [[name, f'{r["angle_deg"]:.0f}', tables.fmt(r['orientation_error_deg'], 1),
           tables.fmt(r['descriptor_distance'], 3), tables.fmt(100 * r['self_match_rate'], 1)]
          for name, sweep in sweeps.items() for r in sweep]
  text = tables.markdown_table(HEADER, rows)
  print(text)
  if FLAGS.out:
    os.makedirs(FLAGS.out, exist_ok=True)
    tables.write_csv(os.path.join(FLAGS.out, 'rotation_sweep.csv'), HEADER, rows)
    with open(os.path.join(FLAGS.out, 'rotation_sweep.md'), 'w') as f:
      f.write(f'# Rotation sweep on {FLAGS.cloud}\n\n{text}')
    viz.plot_rotation_sweep(sweeps, os.path.join(FLAGS.out, 'rotation_sweep.png'))
    print(f'wrote {FLAGS.out}/rotation_sweep.csv, .md and .png')


if __name__ == '__main__':
  cli.run(main)
