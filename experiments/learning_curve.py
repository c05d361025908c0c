r"""Learning curves and equal-step ablations: checkpoints of one or more training runs
registered on the test sets beside ISS + FPFH; a CSV, a Markdown table and a PNG plot.

    # every kept checkpoint of one run
    python -m experiments.learning_curve --run=runs/ours --out=runs/curve
    # several runs at equal steps (an ablation)
    python -m experiments.learning_curve --run=paper=runs/abl_paper \
        --run=robust=runs/ours --steps=3000 --out=runs/ablation

Default sets: the synthetic KITTI-style test set as scanned and with each scan turned
by a random yaw (configs/data/synthetic_kitti_yaw.py), the Oxford-style test set and the
re-scan pairs of the real scans (experiments.data.make_real_pairs); --set=NAME=DIR replaces
them. Rerun
while training goes on: finished cells are read back from OUT/learning_curve.csv.
"""

import dataclasses
import os

from absl import app
from absl import flags

from ssd_jax import inference, viz
from ssd_jax.infra import checkpoint, cli
from ssd_jax.data import registration_sets
from ssd_jax.evaluation import learning_curve, registration, tables
from ssd_jax.infra.logging_utils import quiet_libraries
from ssd_jax.registration import features

FLAGS = flags.FLAGS
flags.DEFINE_multi_string('run', None, 'Training workdir, or NAME=DIR (repeatable).')
flags.DEFINE_string('out', None, 'Output directory (default RUN/learning_curve).')
flags.DEFINE_list('steps', [], 'Checkpoint steps to evaluate (default: every one kept).')
flags.DEFINE_multi_string('set', ['kitti_synthetic=data_cache/synthetic_small/test_kitti',
                                  'kitti_yaw_synthetic=data_cache/synthetic_kitti_yaw/test_kitti',
                                  'oxford_synthetic=data_cache/synthetic_small/test_oxford',
                                  'real_rescan=data_cache/real_pairs'],
                          'NAME=DIR of a registration test set (repeatable).')
flags.DEFINE_list('baselines', ['iss+fpfh'], 'Baseline rows evaluated once per set.')
flags.DEFINE_integer('seed', 0, 'RANSAC seed.')
flags.DEFINE_integer('fpfh_max_nn', features.FPFH_MAX_NN, 'Neighbour cap of the FPFH search.')
flags.DEFINE_integer('num_samples', 0, 'Describe with this many points per cluster '
                     '(0: as the checkpoint says).')
flags.DEFINE_integer('draws', 0, 'Average this many samplings of each ball (0: as the '
                     'checkpoint says).')
flags.mark_flags_as_required(['run'])

# The default sets and the commands that make them.
_MADE_BY = {
    'data_cache/synthetic_small/test_kitti': 'python -m experiments.data.make_synthetic '
                                             '--config=configs/data/synthetic_small.py '
                                             '--out=data_cache/synthetic_small',
    'data_cache/synthetic_small/test_oxford': 'python -m experiments.data.make_synthetic '
                                              '--config=configs/data/synthetic_small.py '
                                              '--out=data_cache/synthetic_small',
    'data_cache/synthetic_kitti_yaw/test_kitti': 'python -m experiments.data.make_synthetic '
                                                 '--config=configs/data/synthetic_kitti_yaw.py '
                                                 '--out=data_cache/synthetic_kitti_yaw',
    'data_cache/real_pairs': 'python -m experiments.data.make_real_pairs',
}


def _named(spec: str, what: str) -> tuple[str, str]:
  name, sep, path = spec.partition('=')
  if not sep:
    return os.path.basename(os.path.normpath(spec)), spec
  if not name or not path:
    raise ValueError(f'--{what} {spec!r} must be NAME=DIR or DIR')
  return name, path


def _describing(model: inference.Model) -> inference.Model:
  """The model with the --num_samples / --draws overrides."""
  return dataclasses.replace(model, num_samples=FLAGS.num_samples or model.num_samples,
                             draws=FLAGS.draws or model.draws)


def markdown(records: list[dict]) -> str:
  header = ['set', 'run', 'step', 'row', 'pairs', 'success (%)', 'RTE (m)', 'RRE (°)',
            'avg #iter', 'precision @ 1 m (%)'] + [
                f'success, yaw {lo}-{hi}° (%)' for lo, hi in registration.YAW_BINS]
  order = sorted(records, key=lambda r: (r['set'], r['run'], int(r['step'] or -1)))
  rows = [[r['set'], r['run'] or '-', r['step'] or '-', r['row'], r['pairs'],
           *(tables.fmt(float(r[k]), d) for k, d in (('success', 1), ('rte', 3), ('rre', 2),
                                                     ('trials', 0), ('precision_1m', 1))),
           *(tables.fmt(float(r[f'success_yaw_{lo}_{hi}']), 0)
             for lo, hi in registration.YAW_BINS)] for r in order]
  return tables.markdown_table(header, rows)


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  quiet_libraries()
  runs = dict(_named(spec, 'run') for spec in FLAGS.run)
  out = FLAGS.out or os.path.join(next(iter(runs.values())), 'learning_curve')
  sets = {}
  for spec in FLAGS.set:
    name, path = _named(spec, 'set')
    if not os.path.exists(path) and path in _MADE_BY:
      raise ValueError(f'{path}: no such test set; make it with {_MADE_BY[path]} '
                       '(or leave it out with --set=NAME=DIR for the sets you have)')
    sets[name] = registration_sets.read_registration_set(path)
  wanted = [int(s) for s in FLAGS.steps]
  checkpoints = []
  for name, path in runs.items():
    ckpt = checkpoint.Checkpointer(inference.checkpoint_directory(path), asynchronous=False)
    kept = ckpt.all_steps()
    ckpt.close()
    absent = sorted(set(wanted) - set(kept))
    if absent:
      raise ValueError(f'{path}: no checkpoint at steps {absent} (kept: {kept})')
    checkpoints += [(name, step) for step in (wanted or kept)]
  os.makedirs(out, exist_ok=True)
  records = learning_curve.run(sets, checkpoints, lambda r, s: _describing(
                                   inference.load(runs[r], s)),
                               os.path.join(out, 'learning_curve.csv'), FLAGS.baselines,
                               FLAGS.seed, progress=True, fpfh_max_nn=FLAGS.fpfh_max_nn)
  text = markdown(records)
  with open(os.path.join(out, 'learning_curve.md'), 'w') as f:
    f.write(f'# Registration of {", ".join(f"{k} ({v})" for k, v in runs.items())}\n\n{text}')
  viz.plot_learning_curve(records, os.path.join(out, 'learning_curve.png'))
  print(text)
  print(f'wrote {out}/learning_curve.csv, .md and .png')


def console():
  """The `ssd-jax-learning-curve` command (pyproject.toml)."""
  cli.run(main)


if __name__ == '__main__':
  console()
