r"""How realistic is the synthetic data? Side-by-side scan statistics against the real
KITTI scans beside the project, and the ISS + FPFH + RANSAC baseline (docs/method.md §4)
on the synthetic KITTI-style test pairs.

    python -m experiments.synthetic_report --data=data_cache/synthetic_small \
        [--real=../shared/data] [--out=runs/synthetic_report.md] [--max_pairs=0]
"""

import json
import os
import time

from absl import app
from absl import flags

from ssd_jax import cli
from ssd_jax.data import benchmarks
from ssd_jax.evaluation import feature_store, registration, tables
from ssd_jax.registration import metrics
from ssd_jax.synthetic import dataset, realism

FLAGS = flags.FLAGS
flags.DEFINE_string('data', 'data_cache/synthetic_small', 'A make_synthetic output directory.')
flags.DEFINE_string('real', os.environ.get('SSD_JAX_SHARED_DATA', '../shared/data'),
                    'Real data root with kitti_object_velodyne/ and example/.')
flags.DEFINE_string('out', None, 'Write the Markdown report here (and JSON beside it).')
flags.DEFINE_integer('max_pairs', 0, 'Evaluate at most this many pairs (0 = all).')
flags.DEFINE_integer('fpfh_max_nn', 1000, 'Neighbour cap of the 4 m normal/FPFH searches.')
flags.DEFINE_integer('scan_stride', 6, 'Every n-th test scan enters the statistics.')


def baseline_table(data: str, max_pairs: int, max_nn: int) -> tuple[str, dict, list]:
  """ISS + FPFH + RANSAC on the KITTI-style test pairs, as Table II registers them, with
  the paper's Oxford row beside."""
  pairs = benchmarks.read_registration_set(os.path.join(data, 'test_kitti'))
  pairs = pairs[:max_pairs] if max_pairs else pairs
  start = time.perf_counter()
  results = registration.register_pairs(pairs, ['iss+fpfh'], feature_store.FeatureStore(
      {}, fpfh_max_nn=max_nn), desc='ISS+FPFH+RANSAC')['iss+fpfh']
  header, table = registration.registration_table({'iss+fpfh': results}, ['iss+fpfh'], {},
                                                  'oxford')
  return (tables.markdown_table(header, table),
          {**metrics.summarize(results), 'seconds': time.perf_counter() - start}, results)


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  if dataset.read_manifest(FLAGS.data) is None:
    raise SystemExit(f'error: {FLAGS.data} is not a synthetic dataset (run '
                     'experiments.make_synthetic first)')
  real_md, real_stats = realism.compare_with_real(FLAGS.data, FLAGS.real, FLAGS.scan_stride)
  base_md, base_stats, per_pair = baseline_table(FLAGS.data, FLAGS.max_pairs, FLAGS.fpfh_max_nn)
  report = (f'## Synthetic vs real scans\n\n{real_md}\n\n'
            f'## ISS + FPFH + RANSAC on the synthetic KITTI-style pairs\n\n{base_md}\n\n'
            f'{base_stats["seconds"]:.0f} s for {base_stats["pairs"]} pairs.\n')
  print(report)
  if FLAGS.out:
    os.makedirs(os.path.dirname(os.path.abspath(FLAGS.out)), exist_ok=True)
    with open(FLAGS.out, 'w') as f:
      f.write(report)
    with open(os.path.splitext(FLAGS.out)[0] + '.json', 'w') as f:
      json.dump({'realism': real_stats, 'baseline': base_stats, 'pairs': per_pair}, f, indent=1)


if __name__ == '__main__':
  cli.run(main)
