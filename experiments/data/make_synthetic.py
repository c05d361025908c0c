r"""Generate the synthetic LiDAR dataset (or reuse it when `--out` already holds it).

    python -m experiments.data.make_synthetic --config=configs/data/synthetic_small.py \
        --out=data_cache/synthetic_small [--config.seed=1] [--overwrite]
"""

import time

from absl import app
from absl import flags
from tqdm import auto as tqdm

from ssd_jax import viz
from ssd_jax.infra import cli
from ssd_jax.synthetic import dataset

FLAGS = flags.FLAGS
flags.DEFINE_string('out', None, 'Output directory.')
flags.DEFINE_integer('seed', None, 'Overrides config.seed.')
flags.DEFINE_bool('overwrite', False, 'Replace a dataset made with a different config.')
flags.DEFINE_bool('progress_bar', True, 'Show a progress bar.')
flags.DEFINE_string('figure', None, 'Also draw raw scan 4 of test_kitti/00 to this PNG '
                    '(top view + perspective, coloured by height).')
cli.define_config_file('config', 'configs/data/synthetic_small.py', 'Synthetic-data config.')
flags.mark_flags_as_required(['out'])


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  config = FLAGS.config
  if FLAGS.seed is not None:
    config.seed = FLAGS.seed
  dataset.check_config(config)
  existing = dataset.read_manifest(FLAGS.out)
  total = dataset.count_scans(config)
  start = time.perf_counter()
  with tqdm.tqdm(total=total, desc='synthetic scans', unit='scan', dynamic_ncols=True,
                 disable=not FLAGS.progress_bar or existing is not None) as bar:
    manifest = dataset.generate(config, FLAGS.out, progress=bar.update,
                                overwrite=FLAGS.overwrite)
  seconds = time.perf_counter() - start
  counts = ', '.join(f'{k} {v}' for k, v in manifest['counts'].items())
  if manifest['reused']:
    print(f'reusing the synthetic dataset in {FLAGS.out} ({counts})')
  else:
    print(f'wrote {FLAGS.out}: {total} scans in {seconds:.0f} s ({seconds / total:.2f} s/scan); '
          f'{counts}')
  if FLAGS.figure and config.test_kitti.num_scenes:
    drive = dataset.make_drive(config, 'test_kitti', 0)
    points = drive.scan(min(4, len(drive.poses) - 1))
    viz.plot_scan(points, FLAGS.figure, f'synthetic HDL-64E scan ({len(points):,} points, '
                  f'seed {config.seed}, test_kitti/00)')
    print(f'figure: {FLAGS.figure}')


def console():
  """The `ssd-jax-make-synthetic` command (pyproject.toml)."""
  cli.run(main)


if __name__ == '__main__':
  console()
