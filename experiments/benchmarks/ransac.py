r"""RANSAC speed: this project's batched RANSAC vs Open3D's, on the same correspondences.

    python -m experiments.benchmarks.ransac --dataset=data_cache/synthetic_small/test_kitti \
        [--max_pairs=60]
    # upright RANSAC's samplings (options.SAMPLINGS), matching included
    python -m experiments.benchmarks.ransac --estimator=upright \
        --dataset=data_cache/cross_sensor/synthetic [--max_pairs=60]

Correspondences: ISS keypoints + FPFH (neighbour cap 200 for speed) + nearest
neighbour, per synthetic test pair. Both estimators get the same 1 m inlier
threshold, 99 % confidence and 10,000-trial cap; Open3D's
`registration_ransac_based_on_correspondence` runs multi-threaded. Prints the
median time per pair and the success rate against the ground truth, plus the
sequential numpy reference (same samples and trial count as the batched one).

`--estimator=upright`: 1,024 farthest-point keypoints + FPFH (cap 200) per cloud, then
`pair_stages.estimate` (matching and upright RANSAC) with uniform and with compatible samples;
median time per pair, success and the median trials. On the synthetic cross-sensor test
set (60 pairs, 2-core AMD EPYC VM): docs/registration.md.
"""

import time

from absl import app
from absl import flags
import numpy as np
from tqdm import auto as tqdm

from ssd_jax.infra import cli
from ssd_jax.data import io, registration_sets
from ssd_jax.registration import matching, metrics, ransac
from ssd_jax.registration import cloud_features, pair_stages
from ssd_jax.registration import options as options_lib

FLAGS = flags.FLAGS
flags.DEFINE_string('dataset', 'data_cache/synthetic_small/test_kitti', 'Registration test set.')
flags.DEFINE_integer('max_pairs', 60, 'Pairs to use (0 = all).')
flags.DEFINE_integer('repeats', 3, 'Timed repeats per pair and method (median taken).')
flags.DEFINE_enum('estimator', 'rigid', options_lib.ESTIMATORS, 'rigid: the paper\'s RANSAC '
                  'against Open3D\'s; upright: its samplings against each other.')


def open3d_ransac(xyz1, xyz2, max_trials, confidence, threshold, seed):
  import open3d as o3d  # pylint: disable=g-import-not-at-top
  reg = o3d.pipelines.registration
  o3d.utility.random.seed(seed)
  pcd = lambda p: o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p))
  corres = o3d.utility.Vector2iVector(np.stack([np.arange(len(xyz1))] * 2, 1).astype(np.int32))
  result = reg.registration_ransac_based_on_correspondence(
      pcd(xyz2), pcd(xyz1), corres, threshold, reg.TransformationEstimationPointToPoint(False), 3,
      [], reg.RANSACConvergenceCriteria(max_trials, confidence))
  return np.asarray(result.transformation)


def upright_samplings(pairs) -> None:
  """Prints matching + upright RANSAC per pair with each sampling but 'auto'."""
  cache, rows = {}, {s: [] for s in options_lib.SAMPLINGS if s != 'auto'}
  for n, pair in enumerate(tqdm.tqdm(pairs, desc='pairs', unit='pair')):
    for path in (pair.cloud1, pair.cloud2):
      if path not in cache:
        cache[path] = cloud_features.cloud_features(io.read_cloud(path), 'auto', 'fpfh',
                                                    fpfh_max_nn=200)
    for sampling in rows:
      times = []
      for _ in range(FLAGS.repeats):
        start = time.perf_counter()
        reg = pair_stages.estimate(cache[pair.cloud1], cache[pair.cloud2], seed=n,
                                   estimator='upright', sampling=sampling)
        times.append(time.perf_counter() - start)
      rows[sampling].append((float(np.median(times)), reg.trials,
                             metrics.registration_errors(pair.transform, reg.transform)['success']))
  print(f'\n{len(pairs)} pairs of {FLAGS.dataset}; farthest-point keypoints + FPFH; upright '
        'RANSAC, threshold 1 m, confidence 0.99, at most 10,000 trials\n')
  print('| sampling | median time per pair (s) | mean (s) | median trials | success |\n'
        '|---|---|---|---|---|')
  for name, r in rows.items():
    t = np.array([x[0] for x in r])
    print(f'| {name} | {np.median(t):.3f} | {t.mean():.3f} | '
          f'{np.median([x[1] for x in r]):.0f} | {100 * np.mean([x[2] for x in r]):.1f} % |')


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  pairs = registration_sets.read_registration_set(FLAGS.dataset)
  if FLAGS.max_pairs:
    pairs = pairs[:FLAGS.max_pairs]
  if FLAGS.estimator == 'upright':
    return upright_samplings(pairs)
  cache = {}
  rows = {'this project (batched)': [], 'Open3D': [], 'sequential numpy (reference)': []}
  for n, pair in enumerate(tqdm.tqdm(pairs, desc='pairs', unit='pair')):
    for path in (pair.cloud1, pair.cloud2):
      if path not in cache:
        pts = io.read_cloud(path)
        cache[path] = cloud_features.cloud_features(pts, 'iss', 'fpfh', fpfh_max_nn=200)
    f1, f2 = cache[pair.cloud1], cache[pair.cloud2]
    nn = matching.nearest_neighbour_matches(f1.descriptors, f2.descriptors)
    xyz1, xyz2 = f1.xyz.astype(np.float64), f2.xyz[nn].astype(np.float64)
    samples = ransac.draw_minimal_samples(np.random.default_rng(n), xyz2, 10_001)
    methods = {
        'this project (batched)': lambda: ransac.ransac(xyz1, xyz2, samples).transform,
        'Open3D': lambda: open3d_ransac(xyz1, xyz2, 10_000, 0.99, 1.0, n),
        'sequential numpy (reference)':
            lambda: ransac.ransac_sequential(xyz1, xyz2, samples).transform,
    }
    for name, fn in methods.items():
      times = []
      for _ in range(FLAGS.repeats if name != 'sequential numpy (reference)' else 1):
        start = time.perf_counter()
        t = fn()
        times.append(time.perf_counter() - start)
      rows[name].append((float(np.median(times)),
                         metrics.registration_errors(pair.transform, t)['success']))
  print(f'\n{len(pairs)} pairs of {FLAGS.dataset}; ISS + FPFH correspondences; threshold 1 m, '
        'confidence 0.99, at most 10,000 trials\n')
  print('| RANSAC | median time per pair (s) | mean (s) | success |\n|---|---|---|---|')
  for name, r in rows.items():
    t = np.array([x[0] for x in r])
    print(f'| {name} | {np.median(t):.3f} | {t.mean():.3f} | '
          f'{100 * np.mean([x[1] for x in r]):.1f} % |')


if __name__ == '__main__':
  cli.run(main)
