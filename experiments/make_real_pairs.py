r"""Registration pairs from the real scans beside the project (a re-scan of each scan
from a displaced, turned virtual sensor; `ssd_jax.data.rescan`).

    python -m experiments.make_real_pairs --real=../shared/data --out=data_cache/real_pairs

Every `.bin` under REAL/example and REAL/kitti_object_velodyne gives --pairs_per_cloud
pairs, one per equal bin of relative yaw over the whole circle. The set is a function of
--seed; the real scans are read, never copied into the project.
"""

import os
from pathlib import Path

from absl import app
from absl import flags
from tqdm import auto as tqdm

from ssd_jax import cli
from ssd_jax.data import io, rescan

FLAGS = flags.FLAGS
flags.DEFINE_string('real', os.environ.get('SSD_JAX_SHARED_DATA', '../shared/data'),
                    'Real data root (example/ and kitti_object_velodyne/).')
flags.DEFINE_string('out', 'data_cache/real_pairs', 'Output directory.')
flags.DEFINE_integer('seed', 0, 'Seed of the virtual sensors.')
flags.DEFINE_integer('pairs_per_cloud', 8, 'Pairs per real scan (one per yaw bin).')


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  sources = [p for sub in ('example', 'kitti_object_velodyne')
             for p in sorted((Path(FLAGS.real) / sub).glob('*.bin'))]
  if not sources:
    raise SystemExit(f'error: {FLAGS.real}: no .bin scans in example/ or '
                     'kitti_object_velodyne/ (set --real or SSD_JAX_SHARED_DATA)')
  try:
    with tqdm.tqdm(total=len(sources) * FLAGS.pairs_per_cloud, desc='re-scan pairs',
                   unit='pair') as bar:
      rows = rescan.make_rescan_set(sources, FLAGS.out, FLAGS.seed, FLAGS.pairs_per_cloud,
                                    progress=bar.update)
  except (io.CloudFileError, ValueError) as e:
    raise SystemExit(f'error: {e}') from None
  print(f'wrote {FLAGS.out}: {len(rows)} pairs from {len(sources)} real scans')


if __name__ == '__main__':
  cli.run(main)
