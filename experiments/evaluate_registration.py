r"""The registration tables (paper Tables I / II) for keypoint x descriptor rows.

    python -m experiments.evaluate_registration --config=configs/registration.py \
        --workdir=runs/registration_synthetic

Writes WORKDIR/registration.md, registration.csv and pairs.jsonl (one line per
pair and row: RTE, RRE (Euler sum and geodesic), success, trials, inliers).
"""

import csv
import json
import os

from absl import app
from absl import flags
import numpy as np
from ml_collections import config_flags
from tqdm import auto as tqdm

from ssd_jax.data import benchmarks, io, pipeline as data_pipeline
from ssd_jax.logging_utils import quiet_libraries
from ssd_jax.registration import metrics, pipeline

FLAGS = flags.FLAGS
flags.DEFINE_string('workdir', None, 'Output directory.')
config_flags.DEFINE_config_file('config', 'configs/registration.py', 'Evaluation config.')
flags.mark_flags_as_required(['workdir'])

NAMES = {'iss': 'ISS', 'random': 'random', 'fpfh': 'FPFH', 'ours': 'Ours',
         '3dfeatnet': '3DFeat-Net'}
# REFERENCE §6: (RTE m, RRE deg, success %, avg #iter) of the paper's own runs.
PAPER = {
    'oxford': {'iss+fpfh': (0.354, 1.43, 93.37, 3239), 'iss+3dfeatnet': (0.314, 1.08, 97.66, 7126),
               'iss+ours': (0.311, 1.01, 98.10, 5648),
               '3dfeatnet+3dfeatnet': (0.304, 1.08, 97.66, 3294),
               '3dfeatnet+ours': (0.310, 1.08, 97.05, 3650)},
    'kitti': {'iss+3dfeatnet': (0.246, 0.627, 93.50, 8311), 'iss+ours': (0.215, 0.510, 93.50, 5960),
              '3dfeatnet+3dfeatnet': (0.264, 0.599, 95.58, 4394),
              '3dfeatnet+ours': (0.258, 0.570, 95.44, 3732)},
}


def row_label(row):
  kp, desc = row.split('+')
  return f'{NAMES.get(kp, kp)} kpt + {NAMES.get(desc, desc)} desc'


def load_models(config, rows):
  """Models named by the rows; a missing checkpoint marks its rows missing."""
  from ssd_jax import inference  # pylint: disable=g-import-not-at-top
  models, missing = {}, {}
  for name in sorted({part for row in rows for part in row.split('+')} - {'iss', 'random', 'fpfh'}):
    path = config.checkpoints.get(name)
    if not path:
      missing[name] = f'no checkpoint configured for {name!r}'
      continue
    try:
      models[name] = inference.load(path)
    except FileNotFoundError as e:
      missing[name] = str(e)
  return models, missing


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  quiet_libraries()
  config = FLAGS.config
  rows = list(config.rows)
  for row in rows:
    if row.count('+') != 1:
      raise SystemExit(f'error: row {row!r} must be "keypoints+descriptor", e.g. iss+fpfh')
  try:
    pairs = benchmarks.read_registration_set(config.dataset)
  except io.CloudFileError as e:
    raise SystemExit(f'error: {e}') from None
  if config.max_pairs:
    pairs = pairs[:config.max_pairs]
  models, missing = load_models(config, rows)
  runnable = [r for r in rows if not set(r.split('+')) & set(missing)]
  os.makedirs(FLAGS.workdir, exist_ok=True)
  clouds, feats, results = {}, {}, {r: [] for r in runnable}

  def features_of(path, row):
    kp, desc = row.split('+')
    key = (path, kp, desc)
    if key not in feats:
      if path not in clouds:
        clouds[path] = data_pipeline.clean_cloud(io.read_cloud(path), str(path))
      pts = clouds[path]
      kp_key = (path, kp)
      if kp_key not in feats:
        feats[kp_key] = pipeline.compute_keypoints(pts, 'learned' if kp in models else kp,
                                                   models.get(kp), config.seed)
      idx = feats[kp_key]
      desc_method = 'learned' if desc in models else desc
      d = pipeline.compute_descriptors(pts, idx, desc_method, models.get(desc),
                                       fpfh_max_nn=config.fpfh_max_nn)
      feats[key] = pipeline.CloudFeatures(pts[idx], d, {})
    return feats[key]

  with open(os.path.join(FLAGS.workdir, 'pairs.jsonl'), 'w') as log:
    for n, pair in enumerate(tqdm.tqdm(pairs, desc='registration', unit='pair')):
      for row in runnable:
        f1, f2 = features_of(pair.cloud1, row), features_of(pair.cloud2, row)
        reg = pipeline.estimate(f1, f2, seed=config.seed * 1_000_003 + n,
                                inlier_threshold=config.inlier_threshold,
                                confidence=config.confidence, max_trials=config.max_trials)
        res = {'row': row, 'sequence': pair.sequence, 'idx1': pair.idx1, 'idx2': pair.idx2,
               'trials': reg.trials, 'inliers': int(reg.inliers.sum()),
               **metrics.registration_errors(pair.transform, reg.transform)}
        results[row].append(res)
        log.write(json.dumps(res) + '\n')
  paper = PAPER.get(config.paper, {})
  header = ['keypoints + descriptor', 'pairs', 'RTE (m)', 'RRE (°)', 'RRE geodesic (°)',
            'success (%)', 'avg #iter', f'paper ({config.paper}): RTE / RRE / success / #iter']
  table = []
  for row in rows:
    ref = paper.get(row)
    ref = ' / '.join(str(v) for v in ref) if ref else '-'
    if row in results:
      s = metrics.summarize(results[row])
      table.append([row_label(row), s['pairs'], f'{s["rte"]:.3f}', f'{s["rre"]:.3f}',
                    f'{s["rre_geodesic"]:.3f}', f'{100 * s["success_rate"]:.2f}',
                    f'{s["trials"]:.0f}', ref])
    else:
      why = '; '.join(v for k, v in missing.items() if k in row.split('+'))
      table.append([row_label(row), 'missing', '-', '-', '-', '-', '-', ref + f' ({why})'])
  md = ['| ' + ' | '.join(header) + ' |', '|' + '---|' * len(header)]
  md += ['| ' + ' | '.join(str(c) for c in r) + ' |' for r in table]
  text = (f'Registration on {config.dataset} ({len(pairs)} pairs). RTE / RRE over successful '
          'pairs (RTE < 2 m, Euler-sum RRE < 5°); success and #iter over all pairs.\n\n' +
          '\n'.join(md) + '\n')
  print(text)
  with open(os.path.join(FLAGS.workdir, 'registration.md'), 'w') as f:
    f.write(text)
  with open(os.path.join(FLAGS.workdir, 'registration.csv'), 'w', newline='') as f:
    csv.writer(f).writerows([header] + table)


if __name__ == '__main__':
  app.run(main)
