r"""The cross-sensor test sets (or reuse them when `--out` already holds them).

    python -m experiments.data.make_cross_sensor --config=configs/data/cross_sensor.py \
        --out=data_cache/cross_sensor [--real=../shared/data] [--overwrite]
    # unlabeled scans of one unit, to adapt a model to it (experiments.adapt)
    python -m experiments.data.make_cross_sensor --scans_of=vlp16 --out=data_cache/scans_vlp16

OUT/synthetic: simulated streets, the reference unit against each other unit 5-40 m
away (`ssd_jax.synthetic.cross_sensor`); OUT/real: the real scans under --real against
re-scans of them by each unit (`ssd_jax.data.rescan.make_cross_sensor_set`), skipped
with a note when --real holds no scans. Both have pairs.tsv naming each pair's sensors
and distance, which `configs/evals/cross_sensor.py` evaluates as a sensor x distance matrix.
"""

import os
from pathlib import Path
import shutil

from absl import app
from absl import flags
from tqdm import auto as tqdm

from ssd_jax import sensors
from ssd_jax.infra import cli
from ssd_jax.data import rescan
from ssd_jax.synthetic import cross_sensor

FLAGS = flags.FLAGS
flags.DEFINE_string('out', 'data_cache/cross_sensor', 'Output directory.')
flags.DEFINE_string('real', os.environ.get('SSD_JAX_SHARED_DATA', '../shared/data'),
                    'Real data root (example/ and kitti_object_velodyne/).')
flags.DEFINE_bool('overwrite', False, 'Replace sets made with a different config.')
flags.DEFINE_list('scans_of', None, 'Instead of the test sets: write unlabeled scans of '
                  'this unit (ssd_jax/sensors.py) along drives through scenes of their own '
                  'to OUT, e.g. to adapt a model to it (experiments.adapt); several units, '
                  'comma-separated, take turns along each drive (a mixed-sensor drive).')
flags.DEFINE_integer('num_scenes', 3, 'With --scans_of: scenes driven through (a scan every '
                     '6 m, ~65 per scene).')
flags.DEFINE_string('poses', None, 'With --scans_of: also write the scans\' ground-truth '
                    'poses to this file (outside OUT; KITTI layout, one line per scan in '
                    'sorted order), to measure labels mined from them (experiments.mine).')
cli.define_config_file('config', 'configs/data/cross_sensor.py', 'Cross-sensor data config.')


def _real_set(config, out: Path) -> str:
  cfg = config.real
  if not cfg.sources:
    return 'the config names no real scans: real set skipped'
  sources = [p for pattern in cfg.sources for p in sorted(Path(FLAGS.real).glob(pattern))]
  if not sources:
    return f'no real scans match {",".join(cfg.sources)} under {FLAGS.real}: real set skipped'
  if (out / 'groundtruths.txt').is_file() and not FLAGS.overwrite:
    return f'reusing {out}'
  if out.exists():
    shutil.rmtree(out)
  total = len(sources) * len(cfg.sensors) * len(cfg.distance_bins) * cfg.pairs_per_cell
  rescan_cfg = rescan.RescanConfig(max_range=cfg.max_range, min_points=500,
                                   toward_points=True)
  with tqdm.tqdm(total=total, desc='real re-scan pairs', unit='pair') as bar:
    rows = rescan.make_cross_sensor_set(sources, out, cfg.sensors, cfg.distance_bins,
                                        cfg.pairs_per_cell, config.seed, rescan_cfg,
                                        progress=bar.update)
  return f'wrote {out}: {len(rows)} pairs from {len(sources)} real scans'


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  config, out = FLAGS.config, Path(FLAGS.out)
  if FLAGS.scans_of:
    for name in FLAGS.scans_of:
      sensors.get(name)
    units = '/'.join(FLAGS.scans_of)
    with tqdm.tqdm(desc=f'{units} scans', unit='scan') as bar:
      n = cross_sensor.write_sensor_scans(config, FLAGS.scans_of, out, FLAGS.num_scenes,
                                          progress=bar.update, poses_out=FLAGS.poses)
    print(f'wrote {out}: {n} unlabeled {units} scans')
    return
  cross_sensor.check_config(config)
  with tqdm.tqdm(total=cross_sensor.count_pairs(config), desc='synthetic pairs',
                 unit='pair') as bar:
    manifest = cross_sensor.generate(config, out / 'synthetic', bar.update, FLAGS.overwrite)
  print(f'{"reusing" if manifest["reused"] else "wrote"} {out / "synthetic"}: '
        f'{manifest["pairs"]} pairs')
  print(_real_set(config, out / 'real'))


def console():
  """The `ssd-jax-make-cross-sensor` command (pyproject.toml)."""
  cli.run(main)


if __name__ == '__main__':
  console()
