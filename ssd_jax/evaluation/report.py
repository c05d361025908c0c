"""Writers of the evaluators (evaluators.py): each
takes an evaluation's results, writes its Markdown, CSV and figure into a folder
and returns the Markdown (figures linked relative to that folder)."""

from __future__ import annotations

import os
from typing import Mapping, Sequence

import numpy as np

from ssd_jax import viz
from ssd_jax.evaluation import (descriptor_matching, feature_store, paper, precision, registration,
                                repeatability, tables)


def _write(workdir: str, name: str, text: str) -> None:
  with open(os.path.join(workdir, name), 'w') as f:
    f.write(text)


def registration_outputs(pairs: Sequence, results: Mapping[str, list], rows: Sequence[str],
                         missing: Mapping[str, str], workdir: str, paper_set: str,
                         description: str, name: str = 'registration') -> str:
  """WORKDIR/{name}.md and .csv: the Table I / II layout; {name}_yaw.csv: success per bin
  of the pairs' relative yaw."""
  header, table = registration.registration_table(results, rows, missing, paper_set)
  yaw_header, yaw_rows = registration.yaw_table(pairs, results, rows)
  tables.write_csv(os.path.join(workdir, f'{name}_yaw.csv'), yaw_header, yaw_rows)
  text = (f'Registration on {description}. RTE / RRE over successful pairs (RTE < 2 m, '
          'Euler-sum RRE < 5°); success and #iter over all pairs.\n\n' +
          tables.markdown_table(header, table) +
          '\nSuccess (%) by the pair\'s relative yaw:\n\n' +
          tables.markdown_table(yaw_header, yaw_rows))
  _write(workdir, f'{name}.md', text)
  tables.write_csv(os.path.join(workdir, f'{name}.csv'), header, table)
  return text


def precision_outputs(results: Mapping[str, dict], rows: Sequence[str],
                      missing: Mapping[str, str], workdir: str, read_at: float,
                      description: str, name: str = 'precision') -> str:
  """WORKDIR/{name}.csv (curves), {name}.md (value at `read_at`) and {name}.png (Fig. 4)."""
  x = precision.THRESHOLDS
  ran = [r for r in rows if r in results]
  tables.write_csv(os.path.join(workdir, f'{name}.csv'), ['x (m)'] + ran,
                   [[f'{v:.1f}'] + [f'{results[r]["curve"][i]:.5f}' for r in ran]
                    for i, v in enumerate(x)])
  header = ['keypoints + descriptor', 'keypoints in overlap / all', f'precision at {read_at:g} m (%)',
            f'paper at {read_at:g} m (%)']
  table = []
  for row in rows:
    ref = paper.PRECISION_AT_1M.get(feature_store.split_row(row)[1]) if read_at == 1.0 else None
    ref = f'~{ref:g}' if ref is not None and not row.startswith('random') else '-'
    if row in results:
      r = results[row]
      table.append([feature_store.row_label(row), f'{len(r["errors"])} / {r["keypoints"]}',
                    tables.fmt(100 * precision.value_at(r['curve'], read_at)), ref])
    else:
      table.append([feature_store.row_label(row), 'missing', '-',
                    f'{ref} ({feature_store.missing_reason(row, missing)})'])
  if ran:
    viz.plot_precision(x, {feature_store.row_label(r): results[r]['curve'] for r in ran},
                       os.path.join(workdir, f'{name}.png'), marker=read_at,
                       title=f'Precision ({description})')
  text = (f'Precision on {description}: share of cloud-1 keypoints (within '
          f'{precision.OVERLAP_RADIUS:g} m of cloud 2) whose descriptor nearest neighbour lies '
          f'within x of its true location.\n\n' + tables.markdown_table(header, table) +
          (f'\n![precision]({name}.png)\n' if ran else ''))
  _write(workdir, f'{name}.md', text)
  return text


def descriptor_matching_outputs(distances: Mapping[str, np.ndarray], labels: np.ndarray,
                                iss_distance: np.ndarray, r_th: Sequence[float],
                                missing: Mapping[str, str], workdir: str, description: str,
                                recall: float = descriptor_matching.RECALL,
                                name: str = 'descriptor_matching') -> str:
  """WORKDIR/{name}.md / .csv (FPR at `recall`, all and ISS-filtered pairs) and
  {name}_roc.png."""
  res = descriptor_matching.filtered_results(distances, labels, iss_distance, r_th, recall)
  cols = ['all pairs'] + [f'r_th = {r:g} m' for r in r_th]
  header = [f'FPR at {100 * recall:g} % recall (%)'] + cols
  table = [['pairs (pos, neg)'] + [f'{p + n} ({p}, {n})' for _, (p, n), _ in res],
           ['paper pairs (pos, neg)', '30000 (15000, 15000)'] +
           ['{} ({}, {})'.format(sum(paper.ISS_FILTERED[r][0]), *paper.ISS_FILTERED[r][0])
            if r in paper.ISS_FILTERED else '-' for r in r_th]]
  for n in list(distances) + [m for m in missing if m not in distances]:
    label = feature_store.NAMES.get(n, n)
    if n in distances:
      table.append([label] + [tables.fmt(100 * f[n]) for _, _, f in res])
    else:
      table.append([label] + ['missing'] * len(cols))
    ref = [paper.DESCRIPTOR_MATCHING.get(n)] + [paper.ISS_FILTERED.get(r, (0, {}))[1].get(n)
                                                for r in r_th]
    if any(v is not None for v in ref):
      table.append([f'{label} (paper)'] + [tables.fmt(v) if v is not None else '-' for v in ref])
  tables.write_csv(os.path.join(workdir, f'{name}.csv'), header, table)
  if distances:
    viz.plot_roc({feature_store.NAMES.get(n, n): descriptor_matching.roc_curve(d, labels)
                  for n, d in distances.items()},
                 os.path.join(workdir, f'{name}_roc.png'), recall=recall,
                 title=f'Descriptor matching ({description})')
  notes = ''.join(f'- {feature_store.NAMES.get(n, n)} missing: {why}\n'
                  for n, why in missing.items())
  text = (f'Descriptor matching on {description}: FPR (%) at {100 * recall:g} % recall, lower '
          'is better; ISS-filtered columns keep pairs whose two clusters both have an ISS '
          'keypoint within r_th of the center. Paper FPFH and 3DFeat-Net numbers on all pairs '
          'are quoted from 3DFeat-Net\'s paper.\n\n' + tables.markdown_table(header, table) +
          (f'\n{notes}' if notes else '') +
          (f'\n![ROC]({name}_roc.png)\n' if distances else ''))
  _write(workdir, f'{name}.md', text)
  return text


def repeatability_outputs(results: Mapping[str, dict], sources: Sequence[str],
                          missing: Mapping[str, str], workdir: str, description: str,
                          radius: float = repeatability.RADIUS,
                          name: str = 'repeatability') -> str:
  """WORKDIR/{name}.md and .csv: repeatability and keypoint count per detector."""
  header = ['keypoints', f'repeatability within {radius:g} m (%)', 'keypoints per cloud']
  table = []
  for s in sources:
    if s in results:
      table.append([feature_store.NAMES.get(s, s), tables.fmt(100 * results[s]['repeatability']),
                    tables.fmt(results[s]['keypoints'], 0)])
    else:
      table.append([feature_store.NAMES.get(s, s), 'missing', missing.get(s, '-')])
  text = (f'Keypoint repeatability on {description}: share of cloud-1 keypoints with a cloud-2 '
          f'keypoint within {radius:g} m after the ground-truth alignment, mean over pairs.\n\n'
          + tables.markdown_table(header, table))
  _write(workdir, f'{name}.md', text)
  tables.write_csv(os.path.join(workdir, f'{name}.csv'), header, table)
  return text
