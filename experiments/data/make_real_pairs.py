r"""Registration pairs from the real scans beside the project (a re-scan of each scan
from a displaced, turned virtual sensor; `ssd_jax.data.rescan`).

    python -m experiments.data.make_real_pairs --real=../shared/data --out=data_cache/real_pairs
    # pairs like RobotCar's test pairs: two submaps of each real Oxford test model
    python -m experiments.data.make_real_pairs --sources=example/oxford_*.bin --submaps \
        --max_range=30 --pairs_per_cloud=24 --out=data_cache/real_oxford_submaps
    # the second view by a 16-beam unit 10-20 m away (experiments.data.make_cross_sensor makes
    # the whole unit x distance set)
    python -m experiments.data.make_real_pairs --sensor=vlp16 --min_shift=10 --max_shift=20 \
        --out=data_cache/real_pairs_vlp16
    # pairs of real drives' own scans, scored against the drives' poses (no re-scan):
    # per drive and distance bin up to --per_bin pairs, each as driven and turned ~180
    # degrees (a revisit from the other heading), with the overlap the poses give
    python -m experiments.data.make_real_pairs --drives=real_drives/* --out=data_cache/real_drives

Every scan matching --sources (default: every `.bin` under REAL/example and
REAL/kitti_object_velodyne) gives --pairs_per_cloud pairs, one per equal bin of relative
yaw. With --drives, each drive folder (scans/NNNNNN.bin + poses.txt,
`ssd_jax.data.real_drives`) gives pairs of its own scans where its pose holds up
(`pose_holds`). The set is a function of --seed; the real scans are read, never copied.
"""

import os
from pathlib import Path

from absl import app
from absl import flags
import numpy as np
from tqdm import auto as tqdm

from ssd_jax import sensors
from ssd_jax.infra import cli
from ssd_jax.data import real_drives, rescan
from ssd_jax.registration import cloud_features, prepared

FLAGS = flags.FLAGS
flags.DEFINE_string('real', os.environ.get('SSD_JAX_SHARED_DATA', '../shared/data'),
                    'Real data root (example/ and kitti_object_velodyne/).')
flags.DEFINE_string('out', 'data_cache/real_pairs', 'Output directory.')
flags.DEFINE_integer('seed', 0, 'Seed of the virtual sensors.')
flags.DEFINE_integer('pairs_per_cloud', 8, 'Pairs per real scan (one per yaw bin).')
flags.DEFINE_list('sources', ['example/*.bin', 'kitti_object_velodyne/*.bin'],
                  'Globs of the real scans, under --real.')
flags.DEFINE_bool('submaps', False, 'The sources are submaps accumulated along a drive '
                  "(RobotCar's test models): the second view is the place within --max_range "
                  'of a displaced, turned centre, with no sensor-centred occlusion.')
flags.DEFINE_string('sensor', '', 'Re-scan the second view with this unit (ssd_jax/sensors.py: '
                    'vlp16, hdl32, hdl64, vls128, front120): only what its beams return.')
flags.DEFINE_float('min_shift', rescan.RescanConfig.min_shift,
                   'Nearest standpoint of the second view, metres.')
flags.DEFINE_float('max_shift', rescan.RescanConfig.max_shift,
                   'Farthest standpoint of the second view, metres.')
flags.DEFINE_float('max_range', rescan.RescanConfig.max_range,
                   'Both views keep what lies within this many metres of their centre.')
flags.DEFINE_list('drives', [], 'Globs of real drive folders under --real (scans/ + '
                  'poses.txt): pairs of their own scans instead of re-scans.')
flags.DEFINE_list('bins', ['0', '2', '5', '10', '20', '30'], 'With --drives: edges of the '
                  'distance bins, metres (pairs 0-2 m apart only where turned >= 20 degrees).')
flags.DEFINE_integer('per_bin', 8, 'With --drives: pairs per drive and distance bin.')
flags.DEFINE_list('tilt', ['0', '0'], 'Degrees lo,hi: tilt the second view\'s sensor by an angle '
                  'in this range about a random horizontal axis (a pitched or rolled unit).')


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  # The flags before the data: a wrong value is named whether or not the scans are there.
  if FLAGS.max_range <= 0:
    raise SystemExit(f'error: --max_range must be > 0, got {FLAGS.max_range}')
  if not 0 <= FLAGS.min_shift <= FLAGS.max_shift:
    raise SystemExit(f'error: need 0 <= --min_shift <= --max_shift, got {FLAGS.min_shift}, '
                     f'{FLAGS.max_shift}')
  try:
    if FLAGS.sensor:
      sensors.get(FLAGS.sensor)
  except ValueError as e:
    raise SystemExit(f'error: --sensor: {e}') from None
  try:
    tilt = tuple(float(t) for t in FLAGS.tilt)
  except ValueError:
    tilt = ()
  if len(tilt) != 2 or not 0 <= tilt[0] <= tilt[1] <= 90:
    raise SystemExit(f'error: --tilt must be lo,hi degrees with 0 <= lo <= hi <= 90, got '
                     f'{",".join(FLAGS.tilt)}')
  if FLAGS.drives:
    return _drives()
  sources = [p for pattern in FLAGS.sources for p in sorted(Path(FLAGS.real).glob(pattern))]
  if not sources:
    raise SystemExit(f'error: {FLAGS.real}: no scans match {",".join(FLAGS.sources)} '
                     '(set --real or SSD_JAX_SHARED_DATA)')
  cfg = rescan.RescanConfig(max_range=FLAGS.max_range, occlusion=not FLAGS.submaps,
                            sensor=FLAGS.sensor, min_shift=FLAGS.min_shift,
                            max_shift=FLAGS.max_shift, tilt=tilt)
  with tqdm.tqdm(total=len(sources) * FLAGS.pairs_per_cloud, desc='re-scan pairs',
                 unit='pair') as bar:
    rows = rescan.make_rescan_set(sources, FLAGS.out, FLAGS.seed, FLAGS.pairs_per_cloud,
                                  cfg, progress=bar.update)
  print(f'wrote {FLAGS.out}: {len(rows)} pairs from {len(sources)} real scans')


# A drive's pose T_12 holds where, under it, at most this share of either scan's structure
# lies where the other's rays passed (`free_space`, as the verdict judges a pose): the right
# poses of the drives beside the project put at most 20 % there (people walking round a
# hand-held unit), Riverside02's from the keyframe where its SLAM odometry runs away along
# a featureless road (to 52 m/s by its end) 26-73 %.
MAX_POSE_CONFLICT = 0.25


def pose_holds(points1: np.ndarray, points2: np.ndarray, t12: np.ndarray) -> bool:
  """Whether a drive's T_12 [4, 4] of two scans [N, 3] (metres, sensors' frames) holds
  up: MAX_POSE_CONFLICT, judged on the register command's grid."""
  grid = lambda p: cloud_features.to_grid(p, cloud_features.VOXEL_SIZE)[0]
  conflict = prepared.PreparedPair(grid(points1), grid(points2)).conflict(t12)
  return conflict is None or conflict <= MAX_POSE_CONFLICT


def _drives():
  try:
    edges = [float(b) for b in FLAGS.bins]
  except ValueError:
    edges = []
  if len(edges) < 2 or any(b >= c for b, c in zip(edges, edges[1:])) or edges[0] < 0:
    raise SystemExit(f'error: --bins must be increasing metres >= 0, got {",".join(FLAGS.bins)}')
  if FLAGS.per_bin < 1:
    raise SystemExit(f'error: --per_bin must be >= 1, got {FLAGS.per_bin}')
  folders = [p for pattern in FLAGS.drives for p in sorted(Path(FLAGS.real).glob(pattern))
             if p.is_dir()]
  if not folders:
    raise SystemExit(f'error: {FLAGS.real}: no drive folders match {",".join(FLAGS.drives)} '
                     '(set --real or SSD_JAX_SHARED_DATA)')
  with tqdm.tqdm(desc='drive pairs', unit='pair') as bar:
    rows = real_drives.make_set(folders, FLAGS.out, list(zip(edges, edges[1:])), FLAGS.per_bin,
                                FLAGS.seed, pose_holds=pose_holds, progress=bar.update)
  print(f'wrote {FLAGS.out}: {len(rows)} pairs from {len(folders)} drives')


if __name__ == '__main__':
  cli.run(main)
