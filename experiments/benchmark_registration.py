r"""Registration speed in the three regimes a user meets, against Open3D's own pipeline.

    python -m experiments.benchmark_registration --dataset=data_cache/real_pairs \
        [--num_pairs=100] [--cold_pairs=3] [--draws=4,1] \
        [--methods=fpfh,learned,open3d_paper,open3d_tutorial] [--dense=2000000] [--tile=20000000]

On the same pairs, for the project's ISS + FPFH, the project's ISS + learned (`ours`,
one row per --draws setting) and a plain Open3D pipeline (`ssd_jax.registration.reference`:
Open3D's ISS with the paper's parameters, normals and FPFH, nearest-neighbour
correspondences, `registration_ransac_based_on_correspondence` at 1 m, 99 %, <= 10,000
trials) with the paper's searches (normals and FPFH within 4 m, no neighbour cap) and
with its tutorial's (1 m / 30-neighbour normals, FPFH capped at 100 neighbours):

  * cold: one pair per new process, the command a user types (wall time of the whole
    command, JAX import and compilation included; the project's persistent
    compilation cache is warmed by one earlier run first, as any second use finds it;
    Open3D's as a plain script that imports Open3D, numpy and the file reader only);
  * warm: one pair in a process that has registered another pair before;
  * batch: `--num_pairs` pairs in one process, each cloud's features once;
  * dense (`--dense=N`): the first pair with each cloud densified to N points (every
    point copied with 5 cm Gaussian jitter, the density of a 128-beam frame or a map
    tile), registered by the command a user types with its defaults (the cloud put on
    the model's 0.2 m grid first) in a new process, with its peak memory; Open3D's
    pipeline on the same clouds after Open3D's own `voxel_down_sample(0.2)` (its
    tutorial's first step; on millions of raw points its ISS does not finish);
  * map tile (`--tile=N`): an accumulated tile of N points, 5 x 5 copies of the first
    pair's cloud 1 on a 40 m grid, each turned by its own yaw so that no shift maps the
    tile onto itself, every point copied with 5 cm jitter; cloud 2 is a second draw of
    that tile moved by the pair's inverse transform (its ground truth: the pair's). The
    register command with its defaults in a new process, wall time and peak memory.

Prints one table: seconds per pair for features (both clouds), matching, RANSAC and
the total, and the success rate (RTE < 2 m, RRE < 5 degrees).
"""

import dataclasses
import json
import os
import subprocess
import sys
import tempfile
import time

from absl import app
from absl import flags
import numpy as np
from tqdm import auto as tqdm

from ssd_jax import cli, pretrained
from ssd_jax.data import clean, io, registration_sets
from ssd_jax.logging_utils import quiet_libraries
from ssd_jax.data import preprocess
from ssd_jax.registration import cloud_features, features, metrics, pair_stages
from ssd_jax.registration.reference import SETTINGS, open3d_register

FLAGS = flags.FLAGS
flags.DEFINE_string('dataset', 'data_cache/synthetic_small/test_kitti', 'Registration set.')
flags.DEFINE_integer('num_pairs', 100, 'Pairs of the batch regime (the first ones).')
flags.DEFINE_integer('cold_pairs', 3, 'Pairs timed as one new process each.')
flags.DEFINE_integer('fpfh_max_nn', features.FPFH_MAX_NN,
                     "The project's FPFH neighbour cap (0: none).")
flags.DEFINE_list('draws', [], 'Learned rows: one per value, describing with this many '
                  "samplings of each ball (default: the shipped model's own setting).")
flags.DEFINE_integer('dense', 0, 'Points per cloud of the dense regime (0: no dense rows), '
                     'e.g. 2000000.')
flags.DEFINE_integer('tile', 0, 'Points per cloud of the map-tile regime (0: none), e.g. '
                     '20000000.')
flags.DEFINE_list('methods', ['fpfh', 'learned', 'open3d_paper', 'open3d_tutorial'],
                  "Rows: fpfh (the project's ISS + FPFH), learned (ISS + ours), open3d_paper "
                  "and open3d_tutorial (the plain Open3D pipeline with the paper's or its "
                  "tutorial's normal and FPFH searches).")

OPEN3D = {f'open3d_{settings}': settings for settings in SETTINGS}
NAMES = {'fpfh': 'project ISS + FPFH', 'learned': 'project ISS + learned',
         **{m: f"Open3D's pipeline, {SETTINGS[s].label}" for m, s in OPEN3D.items()}}


def _read(path) -> np.ndarray:
  return clean.clean_cloud(io.read_cloud(path), str(path), np.float64)


def _runner(method: str, model):
  """-> run(path1, path2, cache, seed) -> (T_12, {stage: seconds}). The project's methods
  keep each cloud's features in `cache` ({path: features}) unless it is None."""
  if method in OPEN3D:
    return lambda path1, path2, cache, seed: open3d_register(_read(path1), _read(path2), seed,
                                                             OPEN3D[method])[:2]
  descriptor = method

  def features_of(path, cache, seed):
    if cache is not None and path in cache:
      return cache[path]
    f = cloud_features.features_anywhere(_read(path), 'iss', descriptor, model, seed,
                                         FLAGS.fpfh_max_nn)
    if cache is not None:
      cache[path] = f
    return f

  def run(path1, path2, cache, seed):
    t0 = time.perf_counter()
    f1, f2 = features_of(path1, cache, seed), features_of(path2, cache, seed)
    features_s = time.perf_counter() - t0
    reg = pair_stages.estimate(f1, f2, seed)
    return reg.transform, {'features': features_s, **reg.seconds}
  return run


def _cold(method: str, pair, draws: int) -> float:
  """Wall seconds of one pair in a new process."""
  if method in OPEN3D:
    # A plain script: Open3D, numpy and the file reader, none of the project's JAX code.
    code = ('import sys; from ssd_jax.data import io; '
            'from ssd_jax.registration.reference import open3d_register; '
            'open3d_register(io.read_cloud(sys.argv[1]), io.read_cloud(sys.argv[2]), '
            'settings=sys.argv[3])')
    cmd = [sys.executable, '-c', code, str(pair.cloud1), str(pair.cloud2), OPEN3D[method]]
  else:
    cmd = [sys.executable, '-m', 'experiments.register', f'--cloud1={pair.cloud1}',
           f'--cloud2={pair.cloud2}', f'--fpfh_max_nn={FLAGS.fpfh_max_nn}',
           f'--descriptor={method}', f'--draws={draws}']
  root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
  t0 = time.perf_counter()
  out = subprocess.run(cmd, cwd=root, capture_output=True, text=True)
  if out.returncode:
    raise SystemExit(f'error: {method} failed in a new process: {out.stderr.strip()[-300:]}')
  return time.perf_counter() - t0


def _densify(path, n: int, out: str, seed: int) -> str:
  """The cloud at `path` as n points (each point copied with 5 cm jitter) in OUT (.bin)."""
  rng = np.random.default_rng(seed)
  pts = _read(path)
  dense = pts[rng.integers(0, len(pts), n)] + rng.normal(0.0, 0.05, (n, 3))
  dense.astype(np.float32).tofile(out)
  return out


def _tile(path, n: int, out: str, seed: int, transform: np.ndarray) -> str:
  """The map tile of the module docstring, n points, moved by `transform` (.bin in OUT)."""
  rng = np.random.default_rng(seed)
  pts = _read(path)
  pts = pts - pts.mean(0)
  angles = np.random.default_rng(0).uniform(-np.pi, np.pi, 25)   # the same tile each draw
  copies = []
  for k, angle in enumerate(angles):
    c, s = np.cos(angle), np.sin(angle)
    shift = np.array([40.0 * (k % 5 - 2), 40.0 * (k // 5 - 2), 0.0])
    copies.append(pts @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T + shift)
  tile = np.concatenate(copies)
  chunks = []
  for lo in range(0, n, 5_000_000):    # bounded temporaries at any n
    idx = rng.integers(0, len(tile), min(n - lo, 5_000_000))
    chunk = tile[idx] + rng.normal(0.0, 0.05, (len(idx), 3))
    chunks.append((chunk @ transform[:3, :3].T + transform[:3, 3]).astype(np.float32))
  np.concatenate(chunks).tofile(out)
  return out


def _register_row(paths, descriptor: str, label: str, regime: str, transform, tmp: str):
  """The register command with its defaults in a new process: a row with its wall time,
  its own peak memory and its success against `transform`."""
  root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
  out_json = os.path.join(tmp, f'{descriptor}.json')
  with open(os.path.join(tmp, 'stderr'), 'w+') as err:
    t0 = time.perf_counter()
    child = subprocess.Popen([sys.executable, '-m', 'experiments.register',
                              f'--cloud1={paths[0]}', f'--cloud2={paths[1]}',
                              f'--descriptor={descriptor}', f'--json={out_json}'], cwd=root,
                             stdout=subprocess.DEVNULL, stderr=err)
    _, status, usage = os.wait4(child.pid, 0)   # this child's own peak memory
    wall = time.perf_counter() - t0
    if status:
      err.seek(0)
      raise SystemExit(f'error: the {regime} {descriptor} run failed: {err.read().strip()[-300:]}')
  with open(out_json) as f:
    t = np.array(json.load(f)['T_12'])
  return (f'register defaults, {descriptor} ({label})',
          f'{regime}: 1 pair, new process, peak {usage.ru_maxrss / 2**20:.2f} GiB', 1,
          {'total': wall}, metrics.registration_errors(transform, t)['success'])


def _tile_rows(pair, n: int) -> list:
  """The map-tile regime's rows (see the module docstring)."""
  with tempfile.TemporaryDirectory() as tmp:
    paths = [_tile(pair.cloud1, n, os.path.join(tmp, f'tile{k}.bin'), k, transform)
             for k, transform in enumerate((np.eye(4), np.linalg.inv(pair.transform)))]
    return [_register_row(paths, d, f'{n:,}-point tile per cloud', 'map tile', pair.transform,
                          tmp) for d in ('learned', 'fpfh') if d in FLAGS.methods]


def _dense_rows(pair, n: int) -> list:
  """The dense regime's rows (see the module docstring)."""
  rows = []
  with tempfile.TemporaryDirectory() as tmp:
    paths = [_densify(c, n, os.path.join(tmp, f'dense{k}.bin'), k)
             for k, c in enumerate((pair.cloud1, pair.cloud2))]
    rows += [_register_row(paths, d, f'{n:,} points per cloud', 'dense', pair.transform, tmp)
             for d in ('learned', 'fpfh') if d in FLAGS.methods]
    if 'open3d_tutorial' in FLAGS.methods:
      t0 = time.perf_counter()
      clouds = [preprocess.voxel_downsample(_read(p), 0.2, np.float64) for p in paths]
      t, stages, _ = open3d_register(clouds[0], clouds[1], 0, 'tutorial')
      rows.append(("Open3D's pipeline, tutorial searches, voxel_down_sample(0.2) first",
                   'dense: 1 pair, in process', 1, {**stages, 'total': time.perf_counter() - t0},
                   metrics.registration_errors(pair.transform, t)['success']))
  return rows


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  quiet_libraries()
  pairs = registration_sets.read_registration_set(FLAGS.dataset)[:FLAGS.num_pairs]
  if len(pairs) < 2:
    raise SystemExit(f'error: {FLAGS.dataset} has {len(pairs)} pair(s); 2 or more needed')
  bad = sorted(set(FLAGS.methods) - set(NAMES))
  if bad:
    raise SystemExit(f'error: --methods must be among {sorted(NAMES)}, got {bad}')
  if FLAGS.dense < 0 or FLAGS.tile < 0:
    raise SystemExit(f'error: --dense and --tile must be >= 0 points (0: none), got '
                     f'{FLAGS.dense} and {FLAGS.tile}')
  shipped = pretrained.load('ours')
  draws = [int(d) for d in FLAGS.draws if d.isdigit() and int(d) > 0] or [shipped.draws]
  if len(draws) != max(len(FLAGS.draws), 1):
    raise SystemExit(f'error: --draws must be positive integers, got {FLAGS.draws}')
  runs = [(m, d) for m in FLAGS.methods for d in (draws if m == 'learned' else [0])]
  rows = []
  for method, d in runs:
    name = NAMES[method] + (f', {d} draw{"s" * (d > 1)}' if method == 'learned' else '')
    model = dataclasses.replace(shipped, draws=d) if method == 'learned' else None
    _cold(method, pairs[0], d)   # fills the compilation cache, as any earlier use would
    cold = [_cold(method, p, d) for p in pairs[:FLAGS.cold_pairs]]
    rows.append((name, 'cold: 1 pair, new process', len(cold), {'total': np.mean(cold)}, None))
    run = _runner(method, model)
    run(pairs[1].cloud1, pairs[1].cloud2, None, 0)   # warm up on another pair
    t0 = time.perf_counter()
    t, stages = run(pairs[0].cloud1, pairs[0].cloud2, None, 0)
    stages['total'] = time.perf_counter() - t0
    rows.append((name, 'warm: 1 pair', 1, stages,
                 metrics.registration_errors(pairs[0].transform, t)['success']))
    cache, success, stages_sum = {}, [], {}
    t0 = time.perf_counter()
    for n, pair in enumerate(tqdm.tqdm(pairs, desc=name, unit='pair')):
      t, stages = run(pair.cloud1, pair.cloud2, cache, n)
      for k, v in stages.items():
        stages_sum[k] = stages_sum.get(k, 0.0) + v
      success.append(metrics.registration_errors(pair.transform, t)['success'])
    batch = {k: v / len(pairs) for k, v in stages_sum.items()}
    batch['total'] = (time.perf_counter() - t0) / len(pairs)
    rows.append((name, f'batch: {len(pairs)} pairs, one process', len(pairs), batch,
                 float(np.mean(success))))
  if FLAGS.dense > 0:
    rows += _dense_rows(pairs[0], FLAGS.dense)
  if FLAGS.tile > 0:
    rows += _tile_rows(pairs[0], FLAGS.tile)
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
