"""How registration quality grows with training, and how runs compare at equal steps:
checkpoints (run, step), each evaluated as Tables I/II on several test sets, beside
fixed baseline rows.

For every checkpoint and test set the row `iss+ours` (ISS keypoints, the checkpoint's
descriptors) gets the registration summary (success, RTE, RRE, #iter), the precision
at 1 m (Fig. 4) and the success split by the pair's relative yaw in 45 degree bins.
Baseline rows (e.g. `iss+fpfh`) get the same once per set.
"""

from __future__ import annotations

import csv
import os
from typing import Callable, Mapping, Sequence

import numpy as np

from ssd_jax.evaluation import feature_store, precision, registration
from ssd_jax.registration import features as features_lib

COLUMNS = (('run', 'step', 'set', 'row', 'pairs', 'success', 'rte', 'rre', 'rre_geodesic', 'trials',
            'precision_1m') + tuple(f'success_yaw_{lo}_{hi}' for lo, hi in registration.YAW_BINS)
           + tuple(f'pairs_yaw_{lo}_{hi}' for lo, hi in registration.YAW_BINS))


def summarize_row(pairs: Sequence, results: Sequence[dict], precision_curve: np.ndarray
                  ) -> dict[str, float]:
  """One CSV row's numbers: success in percent, RTE (m), RRE (deg), mean trials,
  precision at 1 m (percent) and success per yaw bin (percent; NaN for an empty bin)."""
  s = registration.summarize(list(results))
  out = {'pairs': s['pairs'], 'success': 100 * s['success_rate'], 'rte': s['rte'],
         'rre': s['rre'], 'rre_geodesic': s['rre_geodesic'], 'trials': s['trials'],
         'precision_1m': 100 * precision.value_at(precision_curve, 1.0)}
  for (lo, hi), (n, success) in zip(registration.YAW_BINS,
                                    registration.success_by_yaw(pairs, results)):
    out[f'pairs_yaw_{lo}_{hi}'] = n
    out[f'success_yaw_{lo}_{hi}'] = success
  return out


def evaluate_row(pairs: Sequence, row: str, store: feature_store.FeatureStore, seed: int = 0,
                 progress: bool = False, desc: str = '') -> dict[str, float]:
  """Registration and precision of one `keypoints+descriptor` row on one set."""
  results = registration.register_pairs(pairs, [row], store, seed=seed, progress=progress,
                                        desc=desc or row)[row]
  curve = precision.evaluate_precision(pairs, [row], store, progress=False)[row]['curve']
  return summarize_row(pairs, results, curve)


def read_csv(path: str | os.PathLike) -> list[dict]:
  if not os.path.exists(path):
    return []
  with open(path, newline='') as f:
    return list(csv.DictReader(f))


def append_csv(path: str | os.PathLike, record: Mapping) -> None:
  new = not os.path.exists(path)
  with open(path, 'a', newline='') as f:
    writer = csv.DictWriter(f, fieldnames=COLUMNS)
    if new:
      writer.writeheader()
    writer.writerow({k: record.get(k, '') for k in COLUMNS})


def run(sets: Mapping[str, Sequence], checkpoints: Sequence[tuple[str, int]],
        load_model: Callable[[str, int], object], csv_path: str | os.PathLike,
        baseline_rows: Sequence[str] = ('iss+fpfh',), seed: int = 0,
        progress: bool = True, fpfh_max_nn: int = features_lib.FPFH_MAX_NN) -> list[dict]:
  """Evaluate every (run, step) checkpoint on every set, appending to `csv_path`.

  Cells already in the CSV are skipped, so an interrupted curve resumes and a curve
  grows as a run writes new checkpoints. One feature store serves every checkpoint,
  so ISS keypoints are found once per cloud. load_model(run, step) ->
  inference.Model. -> all records of the CSV.
  """
  done = {(r['run'], r['step'], r['set'], r['row']) for r in read_csv(csv_path)}
  store = feature_store.FeatureStore({}, seed, fpfh_max_nn)
  for name, pairs in sets.items():
    for row in baseline_rows:
      if ('', '', name, row) not in done:
        rec = evaluate_row(pairs, row, store, seed, progress, f'{name} {row}')
        append_csv(csv_path, {'run': '', 'step': '', 'set': name, 'row': row, **rec})
  for k, (run_name, step) in enumerate(checkpoints):
    todo = [name for name in sets if (run_name, str(step), name, 'iss+ours') not in done]
    if not todo:
      continue
    model_name = f'checkpoint{k}'
    store.models[model_name] = load_model(run_name, step)
    for name in todo:
      rec = evaluate_row(sets[name], f'iss+{model_name}', store, seed, progress,
                         f'{name} {run_name} step {step}')
      append_csv(csv_path, {'run': run_name, 'step': step, 'set': name, 'row': 'iss+ours',
                            **rec})
    del store.models[model_name]
  return read_csv(csv_path)
