r"""How realistic is the synthetic data? Side-by-side scan statistics against the real
KITTI scans beside the project, and the ISS + FPFH + RANSAC baseline (docs/method.md §4)
on the synthetic KITTI-style test pairs.

    python -m experiments.synthetic_report --data=data_cache/synthetic_small \
        [--real=../shared/data] [--out=runs/synthetic_report.md] [--max_pairs=0]
"""

import glob
import json
import os
import time

from absl import app
from absl import flags
import ml_collections
import numpy as np
from tqdm import auto as tqdm

from ssd_jax import cli
from ssd_jax.data import groundtruth, io
from ssd_jax.registration import features, keypoints, matching, metrics, ransac
from ssd_jax.synthetic import dataset, realism

FLAGS = flags.FLAGS
flags.DEFINE_string('data', 'data_cache/synthetic_small', 'A make_synthetic output directory.')
flags.DEFINE_string('real', os.environ.get('SSD_JAX_SHARED_DATA', '../shared/data'),
                    'Real data root with kitti_object_velodyne/ and example/.')
flags.DEFINE_string('out', None, 'Write the Markdown report here (and JSON beside it).')
flags.DEFINE_integer('max_pairs', 0, 'Evaluate at most this many pairs (0 = all).')
flags.DEFINE_integer('fpfh_max_nn', 1000, 'Neighbour cap of the 4 m normal/FPFH searches.')
flags.DEFINE_integer('scan_stride', 6, 'Every n-th test scan enters the statistics.')


def realism_table(data: str, real: str, stride: int) -> tuple[str, dict]:
  config = ml_collections.ConfigDict(dataset.read_manifest(data)['config'])
  raw, processed = [], []
  for seq in range(config.test_kitti.num_scenes):
    drive = dataset.make_drive(config, 'test_kitti', seq)
    for k in range(0, len(drive.poses), stride):
      raw.append(realism.front_fov(drive.scan(k)))
      processed.append(io.read_cloud(os.path.join(data, 'test_kitti', f'{seq:02d}', f'{k:06d}.bin')))
  real_raw = [io.read_cloud(f) for f in sorted(glob.glob(f'{real}/kitti_object_velodyne/*.bin'))]
  real_proc = [io.read_cloud(f) for f in sorted(glob.glob(f'{real}/example/kitti_*.bin'))]
  cols = {'real KITTI raw (front crop)': real_raw, 'synthetic raw (front crop)': raw,
          'real KITTI processed (0.2 m voxels)': real_proc,
          'synthetic processed (0.2 m voxels)': processed}
  stats = {name: realism.scan_statistics(scans) if scans else None for name, scans in cols.items()}
  keys = next(s for s in stats.values() if s)
  lines = ['| statistic | ' + ' | '.join(cols) + ' |', '|---' * (len(cols) + 1) + '|']
  for key in keys:
    cells = ['n/a' if s is None else (f'{s[key]:,.0f}' if key in ('scans', 'points per scan')
                                      else f'{s[key]:.3f}') for s in stats.values()]
    lines.append(f'| {key} | ' + ' | '.join(cells) + ' |')
  return '\n'.join(lines), stats


def baseline_table(data: str, max_pairs: int, max_nn: int) -> tuple[str, dict, list]:
  pairs = []
  for gt_file in sorted(glob.glob(os.path.join(data, 'test_kitti', '*', 'groundtruths.txt'))):
    folder = os.path.dirname(gt_file)
    pairs += [(folder, p) for p in groundtruth.read_groundtruths(gt_file)]
  if max_pairs:
    pairs = pairs[:max_pairs]
  cache, results = {}, []
  start = time.perf_counter()
  for n, (folder, pair) in enumerate(tqdm.tqdm(pairs, desc='ISS+FPFH+RANSAC', unit='pair')):
    for idx in (pair.idx1, pair.idx2):
      key = (folder, idx)
      if key not in cache:
        pts = io.read_cloud(os.path.join(folder, f'{idx:06d}.bin'))
        kp = keypoints.iss(pts)
        cache[key] = (pts[kp], features.fpfh(pts, kp, max_nn=max_nn))
    (xyz1, f1), (xyz2, f2) = cache[(folder, pair.idx1)], cache[(folder, pair.idx2)]
    nn = matching.nearest_neighbour_matches(f1, f2)
    src = xyz2[nn].astype(np.float64)
    samples = ransac.draw_minimal_samples(np.random.default_rng((0, n)), src, 10_001)
    res = ransac.ransac(xyz1.astype(np.float64), src, samples)
    errs = metrics.registration_errors(pair.transform, res.transform)
    results.append({'sequence': os.path.basename(folder), 'idx1': pair.idx1, 'idx2': pair.idx2,
                    'keypoints': [len(xyz1), len(xyz2)], 'inliers': int(res.inliers.sum()),
                    'trials': res.trials, **errs})
  seconds = time.perf_counter() - start
  s = metrics.summarize(results)
  table = ('| keypoints + descriptor | pairs | RTE (m) | RRE (°) | RRE geodesic (°) | success | '
           'avg #iter |\n|---|---|---|---|---|---|---|\n'
           f'| ISS + FPFH (synthetic KITTI-style) | {s["pairs"]} | {s["rte"]:.3f} | {s["rre"]:.2f} | '
           f'{s["rre_geodesic"]:.2f} | {100 * s["success_rate"]:.2f} % | {s["trials"]:.0f} |\n'
           '| ISS + FPFH (paper, Oxford, Table I) | 828 | 0.354 | 1.43 | - | 93.37 % | 3239 |')
  return table, {**s, 'seconds': seconds}, results


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  if dataset.read_manifest(FLAGS.data) is None:
    raise SystemExit(f'error: {FLAGS.data} is not a synthetic dataset (run '
                     'experiments.make_synthetic first)')
  real_md, real_stats = realism_table(FLAGS.data, FLAGS.real, FLAGS.scan_stride)
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
