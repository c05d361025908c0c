r"""How realistic is the synthetic data? Side-by-side statistics against the real scans
beside the project, and the classic baselines on the synthetic test pairs.

    python -m experiments.diagnostics.synthetic_report --data=data_cache/synthetic_small \
        [--real=../shared/data] [--out=runs/synthetic_report.md] [--max_pairs=0]

For each test split the set holds: KITTI-style scans against the real KITTI scans
(kitti_object_velodyne/, example/kitti_*) and the project's ISS + FPFH + RANSAC on the
pairs; Oxford-style test models against the real RobotCar test models
(example/oxford_*) and, on the pairs, the project's ISS + FPFH + RANSAC and Open3D's own
pipeline (`registration.reference`, the paper's and the tutorial's searches), with the
paper's Oxford row beside.
"""

import json
import os
import time

from absl import app
from absl import flags
import numpy as np
from tqdm import auto as tqdm

from ssd_jax.infra import cli
from ssd_jax.data import clean, io, registration_sets
from ssd_jax.evaluation import feature_store, registration, tables
from ssd_jax.registration import metrics
from ssd_jax.evaluation.reference import SETTINGS, open3d_register
from ssd_jax.synthetic import dataset, realism

FLAGS = flags.FLAGS
flags.DEFINE_string('data', 'data_cache/synthetic_small', 'A make_synthetic output directory.')
flags.DEFINE_string('real', os.environ.get('SSD_JAX_SHARED_DATA', '../shared/data'),
                    'Real data root with kitti_object_velodyne/ and example/.')
flags.DEFINE_string('out', None, 'Write the Markdown report here (and JSON beside it).')
flags.DEFINE_integer('max_pairs', 0, 'Evaluate at most this many pairs per split (0 = all).')
flags.DEFINE_integer('fpfh_max_nn', 0, 'Neighbour cap of the 4 m FPFH search, 0 for none (normals: '
                     '1 m, 30 neighbours).')
flags.DEFINE_integer('scan_stride', 6, 'Every n-th test scan enters the statistics.')
flags.DEFINE_integer('model_stride', 1, 'Every n-th Oxford-style test model enters the '
                     'statistics.')


def baseline_table(split_dir: str, max_pairs: int, max_nn: int, paper_set: str,
                   with_open3d: bool) -> tuple[str, dict, dict]:
  """ISS + FPFH + RANSAC on a split's test pairs, as Tables I/II register them (and
  Open3D's own pipeline when asked), with the paper's row beside -> (Markdown table,
  {row: summary with seconds}, {row: per-pair results})."""
  pairs = registration_sets.read_registration_set(split_dir)
  pairs = pairs[:max_pairs] if max_pairs else pairs
  start = time.perf_counter()
  results = registration.register_pairs(pairs, ['iss+fpfh'], feature_store.FeatureStore(
      {}, fpfh_max_nn=max_nn), desc='ISS+FPFH+RANSAC')
  summaries = {'iss+fpfh': {**registration.summarize(results['iss+fpfh']),
                            'seconds': time.perf_counter() - start}}
  header, table = registration.registration_table(results, ['iss+fpfh'], {}, paper_set)
  for settings in (SETTINGS if with_open3d else ()):
    start = time.perf_counter()
    plain = []
    for n, pair in enumerate(tqdm.tqdm(pairs, desc=f'Open3D pipeline ({settings})', unit='pair')):
      clouds = [clean.clean_cloud(io.read_cloud(p), str(p), np.float64)
                for p in (pair.cloud1, pair.cloud2)]
      t, _, _ = open3d_register(*clouds, seed=n, settings=settings)
      # Open3D does not report its trial count.
      plain.append({**metrics.registration_errors(pair.transform, t), 'trials': float('nan')})
    s = registration.summarize(plain)
    summaries[f'open3d_{settings}'] = {**s, 'seconds': time.perf_counter() - start}
    results[f'open3d_{settings}'] = plain
    table.append([f'Open3D pipeline, {SETTINGS[settings].label}', s['pairs'],
                  tables.fmt(s['rte'], 3), tables.fmt(s['rre'], 3),
                  tables.fmt(s['rre_geodesic'], 3), tables.fmt(100 * s['success_rate']), '-',
                  '-'])
  return tables.markdown_table(header, table), summaries, results


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  if dataset.read_manifest(FLAGS.data) is None:
    raise SystemExit(f'error: {FLAGS.data} is not a synthetic dataset (run '
                     'experiments.data.make_synthetic first)')
  sections, stats = [], {}
  kitti, oxford = (os.path.join(FLAGS.data, split) for split in ('test_kitti', 'test_oxford'))
  if os.path.isdir(kitti):
    real_md, stats['realism_kitti'] = realism.compare_with_real(FLAGS.data, FLAGS.real,
                                                                FLAGS.scan_stride)
    base_md, stats['baseline_kitti'], stats['pairs_kitti'] = baseline_table(
        kitti, FLAGS.max_pairs, FLAGS.fpfh_max_nn, 'oxford', with_open3d=False)
    sections += [f'## Synthetic vs real KITTI scans\n\n{real_md}',
                 f'## ISS + FPFH + RANSAC on the synthetic KITTI-style pairs\n\n{base_md}']
  if os.path.isdir(oxford):
    real_md, stats['realism_oxford'] = realism.compare_oxford_with_real(
        FLAGS.data, FLAGS.real, FLAGS.model_stride)
    base_md, stats['baseline_oxford'], stats['pairs_oxford'] = baseline_table(
        oxford, FLAGS.max_pairs, FLAGS.fpfh_max_nn, 'oxford', with_open3d=True)
    sections += [f'## Synthetic vs real Oxford RobotCar test models\n\n{real_md}',
                 f'## Baselines on the synthetic Oxford-style pairs\n\n{base_md}']
  if not sections:
    raise SystemExit(f'error: {FLAGS.data} holds neither test_kitti/ nor test_oxford/')
  seconds = ', '.join(f'{row} {v["seconds"]:.0f} s for {v["pairs"]} pairs'
                      for key in ('baseline_kitti', 'baseline_oxford') if key in stats
                      for row, v in stats[key].items())
  report = '\n\n'.join(sections) + f'\n\n{seconds}.\n'
  print(report)
  if FLAGS.out:
    os.makedirs(os.path.dirname(os.path.abspath(FLAGS.out)), exist_ok=True)
    with open(FLAGS.out, 'w') as f:
      f.write(report)
    with open(os.path.splitext(FLAGS.out)[0] + '.json', 'w') as f:
      json.dump(stats, f, indent=1, default=float)


if __name__ == '__main__':
  cli.run(main)
