r"""The register command beside the tools a user would pick instead: speed, memory and
success on the same pairs, in every regime a user meets, in one run.

    python -m experiments.benchmarks.registration \
        [--datasets=data_cache/cross_sensor/real,data_cache/real_pairs] [--num_pairs=0] \
        [--methods=register,open3d,kiss_matcher] [--cold_pairs=3] [--loop_scans=12] \
        [--dense=2000000] [--tile=20000000] [--register_flags=--descriptor=fpfh]

Methods, each on every pair of each set (`--num_pairs`: the first N, 0 all):

  * register: `python -m experiments.register` with its defaults (`pretrained.DEFAULT`,
    farthest-point keypoints, 512 then 1,024 where those leave the pose in doubt, upright
    RANSAC, its 10 best poses and the BEV search's 5 verified against the clouds, again
    where the verdict refuses), plus `--register_flags` (e.g.
    `--keypoints=iss,--descriptor=fpfh,--verify=0,--bev=0`: the paper's protocol;
    `--draws=1`: one sampling of each ball).
  * open3d, open3d_tutorial: Open3D's own ISS + FPFH + RANSAC pipeline with the paper's or
    its tutorial's normal and FPFH searches (`ssd_jax.evaluation.reference`).
  * kiss_matcher: KISS-Matcher (PyPI `kiss-matcher`, 0.3 m voxels) and Open3D's
    point-to-plane ICP (1 m, then 0.5 m), the speed to beat; an optional benchmark
    dependency (`pip install -e '.[bench]'`), skipped with one line where it is missing.

Regimes: batch (the register command's `--pairs` in a new process: its per-pair seconds
from registrations.csv and its whole wall time per pair; the anchors in this process);
warm (one pair in a process that registered another before, `pipeline.register_many`);
cold (one pair in a new process after one run filled the persistent compilation cache, as
any second use finds it; the anchors as plain scripts importing Open3D, numpy and the
file reader only); loop closure (`--loop_scans=N`: every pair among the first N clouds
of the first set, timing only); dense (`--dense=N`: the first pair with every point
copied with 5 cm jitter to N points, a 128-beam frame or a map tile, by the command in a
new process with its own peak memory; Open3D's tutorial pipeline after its
`voxel_down_sample(0.2)`); map tile (`--tile=N`: 5 x 5 copies of the first cloud on a
40 m grid, each turned by its own yaw, N points with 5 cm jitter; cloud 2 a second draw
moved by the pair's inverse transform).

Prints per set, method and regime the seconds per pair (median and mean), success (RTE
< 2 m, RRE < 5 degrees) and the ratio to each anchor; then the register command's
seconds per stage (median over the pairs): docs/notes/speed.md has the tables.
"""

import csv
import itertools
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

from ssd_jax import pretrained
from ssd_jax.data import clean, io, preprocess, registration_sets
from ssd_jax.evaluation import reference
from ssd_jax.infra import cli
from ssd_jax.infra.logging_utils import quiet_libraries
from ssd_jax.registration import metrics, pipeline

FLAGS = flags.FLAGS
flags.DEFINE_list('datasets', ['data_cache/cross_sensor/real', 'data_cache/real_pairs'],
                  'Registration sets (experiments.data.make_cross_sensor, make_real_pairs).')
flags.DEFINE_integer('num_pairs', 0, 'Pairs per set (the first ones; 0: all).')
flags.DEFINE_list('methods', ['register', 'open3d', 'kiss_matcher'], 'Rows (`METHODS`).')
flags.DEFINE_integer('cold_pairs', 3, 'Pairs timed as one new process each (first set).')
flags.DEFINE_integer('loop_scans', 12, 'Loop-closure list: every pair among the first N '
                     'clouds of the first set (0: none).')
flags.DEFINE_integer('dense', 0, 'Points per cloud of the dense regime (0: none), e.g. '
                     '2000000.')
flags.DEFINE_integer('tile', 0, 'Points per cloud of the map-tile regime (0: none), e.g. '
                     '20000000.')
flags.DEFINE_float('kiss_voxel', reference.KISS_VOXEL, "KISS-Matcher's voxel size (metres).")
flags.DEFINE_list('register_flags', [], 'Extra flags of the register command, e.g. '
                  '--register_flags=--sampling=uniform (an ablation of its defaults).')

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
NAMES = {'register': f'register, defaults (`{pretrained.DEFAULT}`)',
         'open3d': "Open3D ISS + FPFH + RANSAC (the paper's searches)",
         'open3d_tutorial': "Open3D ISS + FPFH + RANSAC (its tutorial's searches)",
         'kiss_matcher': 'KISS-Matcher + Open3D point-to-plane ICP'}
METHODS = tuple(NAMES)


def _read(path) -> np.ndarray:
  return clean.clean_cloud(io.read_cloud(path), str(path), np.float64)


def _anchor(method: str, p1: np.ndarray, p2: np.ndarray, seed: int = 0) -> np.ndarray:
  if method == 'kiss_matcher':
    return reference.kiss_matcher_register(p1, p2, FLAGS.kiss_voxel)
  return reference.open3d_register(p1, p2, seed, 'tutorial' if method == 'open3d_tutorial'
                                   else 'paper')[0]


def _in_process(method: str, pairs) -> tuple[list[float], list[bool]]:
  """An anchor over the pairs in this process -> (seconds per pair, success per pair)."""
  seconds, success = [], []
  for n, pair in enumerate(tqdm.tqdm(pairs, desc=method, unit='pair', leave=False)):
    t0 = time.perf_counter()
    t = _anchor(method, _read(pair.cloud1), _read(pair.cloud2), n)
    seconds.append(time.perf_counter() - t0)
    success.append(bool(metrics.registration_errors(pair.transform, t)['success']))
  return seconds, success


def _register_command(pairs: list[tuple[str, str]], tmp: str) -> tuple[float, list[dict]]:
  """The register command over `pairs` in a new process -> (wall seconds, CSV rows)."""
  pairs_file, out = os.path.join(tmp, 'pairs.txt'), os.path.join(tmp, 'out')
  with open(pairs_file, 'w') as f:
    f.writelines(f'{os.path.abspath(a)} {os.path.abspath(b)}\n' for a, b in pairs)
  t0 = time.perf_counter()
  run = subprocess.run([sys.executable, '-m', 'experiments.register', f'--pairs={pairs_file}',
                        f'--out={out}', '--noprogress', *FLAGS.register_flags], cwd=ROOT,
                       capture_output=True, text=True)
  wall = time.perf_counter() - t0
  # Pairs it could not register (loop-closure candidates that do not overlap) end the
  # command non-zero with their rows written; anything else is a failure of the benchmark.
  csv_path = os.path.join(out, 'registrations.csv')
  if run.returncode and not (run.stderr.rstrip().endswith('registers only those)')
                             and os.path.exists(csv_path)):
    raise SystemExit(f'error: the register command failed: {run.stderr.strip()[-300:]}')
  with open(csv_path) as f:
    return wall, list(csv.DictReader(f))


def _one_pair(method: str, paths, tmp: str) -> tuple[float, np.ndarray, float]:
  """One pair in a new process -> (wall seconds, T_12, its own peak memory in GiB)."""
  if method == 'register':
    out_json = os.path.join(tmp, 'one_pair.json')
    cmd = [sys.executable, '-m', 'experiments.register', f'--cloud1={paths[0]}',
           f'--cloud2={paths[1]}', f'--json={out_json}', *FLAGS.register_flags]
  else:   # a plain script: Open3D, numpy and the file reader, none of the project's JAX code
    out_json = os.path.join(tmp, 'anchor.npy')
    call = ('reference.kiss_matcher_register(a, b, float(sys.argv[4]))'
            if method == 'kiss_matcher' else 'reference.open3d_register(a, b, settings='
            f'{"tutorial" if method == "open3d_tutorial" else "paper"!r})[0]')
    cmd = [sys.executable, '-c', 'import sys, numpy as np; from ssd_jax.data import io; '
           'from ssd_jax.evaluation import reference; '
           'a, b = (io.read_cloud(p).astype(float) for p in sys.argv[1:3]); '
           f'np.save(sys.argv[3], {call})', str(paths[0]), str(paths[1]), out_json,
           str(FLAGS.kiss_voxel)]
  with open(os.path.join(tmp, 'stderr'), 'w+') as err:
    t0 = time.perf_counter()
    child = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=err)
    _, status, usage = os.wait4(child.pid, 0)   # this child's own peak memory
    wall = time.perf_counter() - t0
    if status:
      err.seek(0)
      raise SystemExit(f'error: {method} failed in a new process: {err.read().strip()[-300:]}')
  if method == 'register':
    with open(out_json) as f:
      t = np.array(json.load(f)['T_12'])
  else:
    t = np.load(out_json)
  return wall, t, usage.ru_maxrss / 2**20


def _densify(path, n: int, out: str, seed: int, transform=None, copies: int = 1) -> str:
  """The cloud at `path` as n points, each copied with 5 cm jitter (`copies` 25: the map
  tile of the module docstring, the same tile each draw), moved by `transform`, as OUT
  (.bin, float32), in chunks so that any n fits in memory."""
  rng = np.random.default_rng(seed)
  pts = _read(path)
  if copies > 1:
    pts = pts - pts.mean(0)
    angles = np.random.default_rng(0).uniform(-np.pi, np.pi, copies)
    pts = np.concatenate([
        pts @ np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]]).T
        + [40.0 * (k % 5 - 2), 40.0 * (k // 5 - 2), 0.0] for k, a in enumerate(angles)])
  transform = np.eye(4) if transform is None else transform
  with open(out, 'wb') as f:
    for lo in range(0, n, 5_000_000):
      chunk = pts[rng.integers(0, len(pts), min(n - lo, 5_000_000))]
      chunk = chunk + rng.normal(0.0, 0.05, chunk.shape)
      (chunk @ transform[:3, :3].T + transform[:3, 3]).astype(np.float32).tofile(f)
  return out


def _big_rows(pair, methods, n: int, tile: bool) -> list:
  """The dense or the map-tile regime's rows (the module docstring)."""
  name = f'{n:,}-point tile per cloud' if tile else f'{n:,} points per cloud'
  rows = []
  with tempfile.TemporaryDirectory() as tmp:
    paths = [_densify(pair.cloud1 if tile else c, n, os.path.join(tmp, f'{k}.bin'), k,
                      np.linalg.inv(pair.transform) if tile and k else None, 25 if tile else 1)
             for k, c in enumerate((pair.cloud1, pair.cloud2))]
    if 'register' in methods:
      wall, t, peak = _one_pair('register', paths, tmp)
      rows.append((name, 'register', f'1 pair, new process, peak {peak:.2f} GiB', 1, [wall],
                   [metrics.registration_errors(pair.transform, t)['success']]))
    if 'open3d_tutorial' in methods and not tile:
      t0 = time.perf_counter()
      clouds = [preprocess.voxel_downsample(_read(p), 0.2, np.float64) for p in paths]
      t = _anchor('open3d_tutorial', *clouds)
      rows.append((name, 'open3d_tutorial', 'voxel_down_sample(0.2) first, in process', 1,
                   [time.perf_counter() - t0],
                   [metrics.registration_errors(pair.transform, t)['success']]))
  return rows


def _transform(row: dict) -> np.ndarray:
  return np.array([float(row[f'T_12[{i}][{j}]']) for i in range(4) for j in range(4)]).reshape(4, 4)


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  quiet_libraries()
  bad = sorted(set(FLAGS.methods) - set(METHODS))
  if bad:
    raise SystemExit(f'error: --methods must be among {list(METHODS)}, got {bad}')
  sizes = ('num_pairs', 'cold_pairs', 'loop_scans', 'dense', 'tile')
  if any(FLAGS[s].value < 0 for s in sizes):
    raise SystemExit('error: ' + ', '.join(f'--{s}' for s in sizes) + ' must be >= 0, got '
                     + ', '.join(str(FLAGS[s].value) for s in sizes))
  sets = {d: registration_sets.read_registration_set(d) for d in FLAGS.datasets}
  if FLAGS.num_pairs:
    sets = {d: pairs[:FLAGS.num_pairs] for d, pairs in sets.items()}
  methods = list(FLAGS.methods)
  if 'kiss_matcher' in methods and reference.kiss_matcher is None:
    print(f'kiss_matcher: {reference.KISS_MISSING}; its rows are skipped')
    methods.remove('kiss_matcher')
  rows, stage_rows = [], []   # (set, method, regime, pairs, seconds [n], success or None)
  for name, pairs in sets.items():
    if 'register' in methods:
      with tempfile.TemporaryDirectory() as tmp:
        wall, out = _register_command([(p.cloud1, p.cloud2) for p in pairs], tmp)
      ok = [bool(metrics.registration_errors(p.transform, _transform(r))['success'])
            for p, r in zip(pairs, out)]
      rows.append((name, 'register', 'batch (`--pairs`), in its CSV', len(pairs),
                   [float(r['seconds']) for r in out], ok))
      rows.append((name, 'register', 'batch, whole command / pairs', len(pairs),
                   [wall / len(pairs)], None))
      stage_rows.append((name, {s: float(np.median([float(r[f'seconds_{s}'] or 0) for r in out]))
                                for s in pipeline.STAGES}))
    for method in (m for m in methods if m != 'register'):
      seconds, ok = _in_process(method, pairs)
      rows.append((name, method, 'batch, in process', len(pairs), seconds, ok))
  first = next(iter(sets.values()))
  if 'register' in methods and len(first) > 1 and not FLAGS.register_flags:
    # Warm: another pair first, then pair 0 (its own clouds, met for the first time).
    *_, warm = pipeline.register_many(
        [(first[1].cloud1, first[1].cloud2), (first[0].cloud1, first[0].cloud2)], _read,
        model=pretrained.load(pretrained.DEFAULT), say=lambda line: None)
    rows.append(('(first set, pair 0)', 'register', 'warm: 1 pair in process', 1,
                 [warm.seconds], [bool(metrics.registration_errors(
                     first[0].transform, warm.registration.transform)['success'])]))
  if 'register' in methods and FLAGS.loop_scans:
    clouds = list(dict.fromkeys(c for p in first for c in (p.cloud1, p.cloud2)))
    loop = list(itertools.combinations(clouds[:FLAGS.loop_scans], 2))
    with tempfile.TemporaryDirectory() as tmp:
      wall, out = _register_command(loop, tmp)
    name = f'loop closure: every pair of {len(clouds[:FLAGS.loop_scans])} scans'
    rows.append((name, 'register', '`--pairs`, in its CSV', len(loop),
                 [float(r['seconds']) for r in out], None))
    rows.append((name, 'register', 'whole command / pairs', len(loop), [wall / len(loop)],
                 None))
  if FLAGS.cold_pairs:
    for method in methods:
      with tempfile.TemporaryDirectory() as tmp:
        _one_pair(method, (first[0].cloud1, first[0].cloud2), tmp)   # fills the cache
        cold = [_one_pair(method, (p.cloud1, p.cloud2), tmp) for p in first[:FLAGS.cold_pairs]]
      rows.append(('(first set)', method, 'cold: 1 pair, new process', len(cold),
                   [c[0] for c in cold], [metrics.registration_errors(p.transform, c[1])[
                       'success'] for p, c in zip(first, cold)]))
  for n, tile in ((FLAGS.dense, False), (FLAGS.tile, True)):
    if n:
      rows += _big_rows(first[0], methods, n, tile)
  _print(rows, stage_rows)


def _print(rows, stage_rows) -> None:
  """rows: (set, method, regime, pairs, seconds [n], success [n] or None)."""
  kind = lambda regime: 'cold' if regime.startswith('cold') else 'batch'
  anchors = {(name, kind(regime), method): float(np.median(seconds))
             for name, method, regime, _, seconds, _ in rows if method != 'register'}
  flags_note = f' {" ".join(FLAGS.register_flags)}' if FLAGS.register_flags else ''
  print(f'\nseconds per pair; × anchor: the median against the anchor\'s on the same pairs '
        f'and regime{"; register with" + flags_note if flags_note else ""}\n')
  print('| set | method | regime | pairs | median (s) | mean (s) | success | '
        '× KISS-Matcher + ICP | × Open3D |')
  print('|---|---|---|---|---|---|---|---|---|')
  for name, method, regime, n, seconds, ok in rows:
    median = float(np.median(seconds))
    ratio = lambda anchor, key=(name, kind(regime)): (
        '-' if method != 'register' or (*key, anchor) not in anchors
        else f'{median / anchors[(*key, anchor)]:.2f}')
    success = '-' if ok is None else f'{100 * np.mean(ok):.1f} %'
    print(f'| {name} | {NAMES[method]} | {regime} | {n} | {median:.3f} | '
          f'{np.mean(seconds):.3f} | {success} | {ratio("kiss_matcher")} | {ratio("open3d")} |')
  if stage_rows:
    print('\nregister (batch), median seconds per pair by stage\n')
    print('| set | ' + ' | '.join(pipeline.STAGES) + ' |')
    print('|---|' + '---|' * len(pipeline.STAGES))
    for name, stages in stage_rows:
      print(f'| {name} | ' + ' | '.join(f'{stages[s]:.3f}' for s in pipeline.STAGES) + ' |')


if __name__ == '__main__':
  cli.run(main)
