r"""The register command's defaults beside the tools a user would pick instead: speed and
success on the same pairs, in one run.

    python -m experiments.benchmark_register \
        [--datasets=data_cache/cross_sensor/real,data_cache/real_pairs] [--num_pairs=0] \
        [--cold_pairs=3] [--loop_scans=12] [--methods=register,open3d,kiss_matcher] \
        [--register_flags=--sampling=uniform]

Methods, each on every pair of each set (`--num_pairs`: the first N, 0 all):

  * register: `python -m experiments.register` with its defaults (the shipped `ours`,
    farthest-point keypoints, 512 then 1,024 where those leave the pose in doubt, upright
    RANSAC, its 10 best poses and the BEV search's 5 verified against the clouds). batch:
    the whole `--pairs` command in a new process, its wall time per pair (imports, loading
    the model and reading included) and the median of its per-pair seconds
    (registrations.csv, which also gives each stage's seconds); warm: one pair in a
    process that registered another before (the library's `pipeline.register_many`, as the
    command); cold: one pair in a new process, after one run has filled the persistent
    compilation cache, as any second use finds it.
  * open3d: Open3D's own ISS + FPFH + RANSAC pipeline with the paper's searches
    (`ssd_jax.registration.reference`), in process; cold as a plain script that imports
    Open3D, numpy and the file reader only.
  * kiss_matcher: KISS-Matcher (PyPI `kiss-matcher`, 0.3 m voxels, its defaults) and
    Open3D's point-to-plane ICP (1 m, then 0.5 m correspondences), the speed to beat;
    an optional benchmark dependency (`pip install -e '.[bench]'`), skipped with one line
    where it is not installed.

Loop closure (`--loop_scans=N`): the register command over every pair among the first N
clouds of the first set, as a back end's loop-closure candidates meet each scan many
times (timing only: most of those pairs do not overlap).

Prints the table of docs/notes/benchmarks.md: per set and method, seconds per pair (median and
mean), success (RTE < 2 m, RRE < 5 degrees) and the ratio to each anchor; then the
register command's seconds per stage (median over the pairs).
"""

import csv
import itertools
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
from ssd_jax.registration import metrics, pipeline, reference

FLAGS = flags.FLAGS
flags.DEFINE_list('datasets', ['data_cache/cross_sensor/real', 'data_cache/real_pairs'],
                  'Registration sets (experiments.make_cross_sensor, make_real_pairs).')
flags.DEFINE_integer('num_pairs', 0, 'Pairs per set (the first ones; 0: all).')
flags.DEFINE_integer('cold_pairs', 3, 'Pairs timed as one new process each (first set).')
flags.DEFINE_integer('loop_scans', 12, 'Loop-closure list: every pair among the first N '
                     'clouds of the first set (0: none).')
flags.DEFINE_list('methods', ['register', 'open3d', 'kiss_matcher'], 'Rows.')
flags.DEFINE_float('kiss_voxel', reference.KISS_VOXEL, "KISS-Matcher's voxel size (metres).")
flags.DEFINE_list('register_flags', [], 'Extra flags of the register command, e.g. '
                  '--register_flags=--sampling=uniform (an ablation of its defaults).')

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
METHODS = ('register', 'open3d', 'kiss_matcher')
NAMES = {'register': 'register, defaults (`ours`)',
         'open3d': "Open3D ISS + FPFH + RANSAC (the paper's searches)",
         'kiss_matcher': 'KISS-Matcher + Open3D point-to-plane ICP'}


def _read(path) -> np.ndarray:
  return clean.clean_cloud(io.read_cloud(path), str(path), np.float64)


def _in_process(method: str, pairs) -> tuple[list[float], list[bool]]:
  """An anchor over the pairs in this process -> (seconds per pair, success per pair)."""
  seconds, success = [], []
  for n, pair in enumerate(tqdm.tqdm(pairs, desc=method, unit='pair', leave=False)):
    t0 = time.perf_counter()
    p1, p2 = _read(pair.cloud1), _read(pair.cloud2)
    if method == 'open3d':
      t = reference.open3d_register(p1, p2, n, 'paper')[0]
    else:
      t = reference.kiss_matcher_register(p1, p2, FLAGS.kiss_voxel)
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


def _cold(method: str, pair) -> float:
  """Wall seconds of one pair in a new process."""
  if method == 'register':
    cmd = [sys.executable, '-m', 'experiments.register', f'--cloud1={pair.cloud1}',
           f'--cloud2={pair.cloud2}']
  else:
    if method == 'open3d':
      call = "from ssd_jax.registration.reference import open3d_register as r; r(a, b, settings='paper')"
    else:
      call = ('from ssd_jax.registration.reference import kiss_matcher_register as r; '
              f'r(a, b, {FLAGS.kiss_voxel})')
    cmd = [sys.executable, '-c', 'import sys; from ssd_jax.data import io; '
           'a, b = (io.read_cloud(p).astype(float) for p in sys.argv[1:3]); ' + call,
           str(pair.cloud1), str(pair.cloud2)]
  t0 = time.perf_counter()
  run = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
  if run.returncode:
    raise SystemExit(f'error: {method} failed in a new process: {run.stderr.strip()[-300:]}')
  return time.perf_counter() - t0


def _transform(row: dict) -> np.ndarray:
  return np.array([float(row[f'T_12[{i}][{j}]']) for i in range(4) for j in range(4)]).reshape(4, 4)


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  quiet_libraries()
  bad = sorted(set(FLAGS.methods) - set(METHODS))
  if bad:
    raise SystemExit(f'error: --methods must be among {list(METHODS)}, got {bad}')
  if FLAGS.num_pairs < 0 or FLAGS.cold_pairs < 0 or FLAGS.loop_scans < 0:
    raise SystemExit('error: --num_pairs, --cold_pairs and --loop_scans must be >= 0')
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
      per_pair = [float(r['seconds']) for r in out]
      rows.append((name, 'register', 'batch (`--pairs`), in its CSV', len(pairs), per_pair, ok))
      rows.append((name, 'register', 'batch, whole command / pairs', len(pairs),
                   [wall / len(pairs)], None))
      stage_rows.append((name, {s: float(np.median([float(r[f'seconds_{s}'] or 0) for r in out]))
                                for s in pipeline.STAGES}))
    for method in methods[1:] if methods[0] == 'register' else methods:
      seconds, ok = _in_process(method, pairs)
      rows.append((name, method, 'batch, in process', len(pairs), seconds, ok))
  first = next(iter(sets.values()))
  if 'register' in methods:
    # Warm: another pair first, then pair 0 (its own clouds, met for the first time).
    *_, warm = pipeline.register_many(
        [(first[1].cloud1, first[1].cloud2), (first[0].cloud1, first[0].cloud2)], _read,
        model=pretrained.load('ours'), say=lambda line: None)
    rows.append(('(first set, pair 0)', 'register', 'warm: 1 pair in process', 1,
                 [warm.seconds], [bool(metrics.registration_errors(
                     first[0].transform, warm.registration.transform)['success'])]))
    if FLAGS.loop_scans:
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
      _cold(method, first[0])   # fills the compilation cache, as any earlier use would
      cold = [_cold(method, p) for p in first[:FLAGS.cold_pairs]]
      rows.append(('(first set)', method, 'cold: 1 pair, new process', len(cold), cold, None))
  _print(rows, stage_rows)


def _print(rows, stage_rows) -> None:
  """rows: (set, method, regime, pairs, seconds [n], success [n] or None)."""
  kind = lambda regime: 'cold' if regime.startswith('cold') else 'batch'
  anchors = {(name, kind(regime), method): float(np.median(seconds))
             for name, method, regime, _, seconds, _ in rows if method != 'register'}
  print('\nseconds per pair; × anchor: the median against the anchor\'s on the same pairs '
        'and regime\n')
  print('| set | method | regime | pairs | median (s) | mean (s) | success | '
        '× KISS-Matcher + ICP | × Open3D |')
  print('|---|---|---|---|---|---|---|---|---|')
  for name, method, regime, n, seconds, ok in rows:
    median = float(np.median(seconds))
    ratio = lambda anchor: ('-' if method != 'register' or (name, kind(regime), anchor)
                            not in anchors else f'{median / anchors[name, kind(regime), anchor]:.2f}')
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
