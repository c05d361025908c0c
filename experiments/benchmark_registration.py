r"""Registration speed in the three regimes a user meets, against Open3D's own pipeline.

    python -m experiments.benchmark_registration --dataset=data_cache/real_pairs \
        [--num_pairs=100] [--cold_pairs=3]

On the same pairs, for the project's ISS + FPFH, the project's ISS + learned (`ours`)
and a plain Open3D pipeline as its tutorial writes it (Open3D's ISS with the paper's
parameters, FPFH within 4 m and at most 100 neighbours on 1 m / 30-neighbour normals,
nearest-neighbour correspondences,
`registration_ransac_based_on_correspondence` at 1 m, 99 %, <= 10,000 trials):

  * cold: one pair per new process, the command a user types (wall time of the whole
    command, JAX import and compilation included; the project's persistent
    compilation cache is warmed by one earlier run first, as any second use finds it);
  * warm: one pair in a process that has registered another pair before;
  * batch: `--num_pairs` pairs in one process, each cloud's features once.

Prints one table: seconds per pair for features (both clouds), matching, RANSAC and
the total, and the success rate (RTE < 2 m, RRE < 5 degrees).
"""

import os
import subprocess
import sys
import time

from absl import app
from absl import flags
import numpy as np
from scipy import spatial
from tqdm import auto as tqdm

from ssd_jax import cli, pretrained
from ssd_jax.data import benchmarks, clean, io
from ssd_jax.logging_utils import quiet_libraries
from ssd_jax.registration import features, keypoints, matching, metrics, pipeline

FLAGS = flags.FLAGS
flags.DEFINE_string('dataset', 'data_cache/synthetic_small/test_kitti', 'Registration set.')
flags.DEFINE_integer('num_pairs', 100, 'Pairs of the batch regime (the first ones).')
flags.DEFINE_integer('cold_pairs', 3, 'Pairs timed as one new process each.')
flags.DEFINE_integer('fpfh_max_nn', features.FPFH_MAX_NN, "The project's FPFH neighbour cap.")

METHODS = ('project ISS + FPFH', 'project ISS + learned', 'Open3D ISS + FPFH + RANSAC')


def open3d_register(points1: np.ndarray, points2: np.ndarray, seed: int = 0):
  """The plain Open3D pipeline on two clouds [N, 3] -> (T_12, {stage: seconds})."""
  import open3d as o3d  # pylint: disable=g-import-not-at-top
  reg = o3d.pipelines.registration
  t0 = time.perf_counter()
  feats = []
  for points in (points1, points2):
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, np.float64)))
    iss = o3d.geometry.keypoint.compute_iss_keypoints(pcd, **keypoints.ISS_PARAMS)
    # Open3D gives keypoint coordinates; FPFH at their indices comes in ascending order.
    _, idx = spatial.cKDTree(np.asarray(pcd.points)).query(np.asarray(iss.points))
    idx = np.unique(idx)
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=1.0, max_nn=30))
    fpfh = reg.compute_fpfh_feature(pcd, o3d.geometry.KDTreeSearchParamHybrid(
        radius=features.FPFH_RADIUS, max_nn=100), [int(i) for i in idx])
    feats.append((np.asarray(pcd.points)[idx], np.asarray(fpfh.data).T))
  t1 = time.perf_counter()
  nn = matching.nearest_neighbour_matches(feats[0][1], feats[1][1])
  corres = o3d.utility.Vector2iVector(np.stack([nn, np.arange(len(nn))], 1).astype(np.int32))
  t2 = time.perf_counter()
  o3d.utility.random.seed(seed)
  cloud = lambda p: o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p))
  result = reg.registration_ransac_based_on_correspondence(
      cloud(feats[1][0]), cloud(feats[0][0]), corres, 1.0,
      reg.TransformationEstimationPointToPoint(False), 3, [],
      reg.RANSACConvergenceCriteria(10_000, 0.99))
  t3 = time.perf_counter()
  return np.asarray(result.transformation), {'features': t1 - t0, 'matching': t2 - t1,
                                             'ransac': t3 - t2}


def _read(path) -> np.ndarray:
  return clean.clean_cloud(io.read_cloud(path), str(path), np.float64)


def _runner(method: str, model):
  """-> run(path1, path2, cache, seed) -> (T_12, {stage: seconds}). The project's methods
  keep each cloud's features in `cache` ({path: features}) unless it is None."""
  if method.startswith('Open3D'):
    return lambda path1, path2, cache, seed: open3d_register(_read(path1), _read(path2), seed)
  descriptor = 'learned' if 'learned' in method else 'fpfh'

  def features_of(path, cache, seed):
    if cache is not None and path in cache:
      return cache[path]
    f = pipeline.features_anywhere(_read(path), 'iss', descriptor, model, seed, FLAGS.fpfh_max_nn)
    if cache is not None:
      cache[path] = f
    return f

  def run(path1, path2, cache, seed):
    t0 = time.perf_counter()
    f1, f2 = features_of(path1, cache, seed), features_of(path2, cache, seed)
    features_s = time.perf_counter() - t0
    reg = pipeline.estimate(f1, f2, seed)
    return reg.transform, {'features': features_s, **reg.seconds}
  return run


def _cold(method: str, pair) -> float:
  """Wall seconds of one pair in a new process."""
  if method.startswith('Open3D'):
    code = ('import sys, numpy as np; from experiments import benchmark_registration as b; '
            'b.open3d_register(b._read(sys.argv[1]), b._read(sys.argv[2]))')
    cmd = [sys.executable, '-c', code, str(pair.cloud1), str(pair.cloud2)]
  else:
    cmd = [sys.executable, '-m', 'experiments.register', f'--cloud1={pair.cloud1}',
           f'--cloud2={pair.cloud2}', f'--fpfh_max_nn={FLAGS.fpfh_max_nn}',
           '--descriptor=' + ('learned' if 'learned' in method else 'fpfh')]
  root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
  t0 = time.perf_counter()
  out = subprocess.run(cmd, cwd=root, capture_output=True, text=True)
  if out.returncode:
    raise SystemExit(f'error: {method} failed in a new process: {out.stderr.strip()[-300:]}')
  return time.perf_counter() - t0


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  quiet_libraries()
  try:
    pairs = benchmarks.read_registration_set(FLAGS.dataset)[:FLAGS.num_pairs]
  except io.CloudFileError as e:
    raise SystemExit(f'error: {e}') from None
  if len(pairs) < 2:
    raise SystemExit(f'error: {FLAGS.dataset} has {len(pairs)} pair(s); 2 or more needed')
  model = pretrained.load('ours')
  rows = []
  for method in METHODS:
    _cold(method, pairs[0])   # fills the compilation cache, as any earlier use would
    cold = [_cold(method, p) for p in pairs[:FLAGS.cold_pairs]]
    rows.append((method, 'cold: 1 pair, new process', len(cold), {'total': np.mean(cold)}, None))
    run = _runner(method, model)
    run(pairs[1].cloud1, pairs[1].cloud2, None, 0)   # warm up on another pair
    t0 = time.perf_counter()
    t, stages = run(pairs[0].cloud1, pairs[0].cloud2, None, 0)
    stages['total'] = time.perf_counter() - t0
    rows.append((method, 'warm: 1 pair', 1, stages,
                 metrics.registration_errors(pairs[0].transform, t)['success']))
    cache, success = {}, []
    t0 = time.perf_counter()
    for n, pair in enumerate(tqdm.tqdm(pairs, desc=method, unit='pair')):
      t, _ = run(pair.cloud1, pair.cloud2, cache, n)
      success.append(metrics.registration_errors(pair.transform, t)['success'])
    rows.append((method, f'batch: {len(pairs)} pairs, one process', len(pairs),
                 {'total': (time.perf_counter() - t0) / len(pairs)}, float(np.mean(success))))
  print(f'\n{FLAGS.dataset}; seconds per pair (mean)\n')
  print('| method | regime | pairs | features | matching | RANSAC | total | success |')
  print('|---|---|---|---|---|---|---|---|')
  fmt = lambda v: '-' if v is None else f'{v:.3f}'
  for method, regime, n, stages, ok in rows:
    succ = '-' if ok is None else f'{100 * float(ok):.0f} %'
    print(f'| {method} | {regime} | {n} | {fmt(stages.get("features"))} | '
          f'{fmt(stages.get("matching"))} | {fmt(stages.get("ransac"))} | '
          f'{fmt(stages["total"])} | {succ} |')


if __name__ == '__main__':
  cli.run(main)
