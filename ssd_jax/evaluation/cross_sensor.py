"""Cross-sensor registration: every row of a test set whose pairs.tsv names the sensors
and distance of each pair, summarised as a sensor x distance matrix.

Each cell holds success (RTE < 2 m and Euler-sum RRE < 5 degrees), RTE / RRE over its
successful pairs and the inlier ratio (RANSAC inliers / nearest-neighbour matches, mean
over its pairs). Its rows are `registration.register_pairs`': the register command's,
the paper protocol's and the whole-cloud rows (`registration.CLOUD_ROWS`: Open3D's own
pipeline, the outside reference the matrix is read against; KISS-Matcher + ICP; the
bird's-eye-view search alone, its best poses verified).
"""

from __future__ import annotations

import os
from typing import Mapping, Sequence

import numpy as np

from ssd_jax.evaluation import feature_store, registration, tables


def label(row: str) -> str:
  return registration.CLOUD_ROWS.get(row) or feature_store.row_label(row)


def distance_bin(distance: float, bins: Sequence[Sequence[float]]) -> str | None:
  """'lo-hi m' of the bin holding `distance` metres, None outside every bin."""
  for lo, hi in bins:
    if lo <= distance < hi:
      return f'{lo:g}-{hi:g} m'
  return None


def overlap_bin(overlap: float, bins: Sequence[Sequence[float]]) -> str | None:
  """'overlap lo-hi' of the bin holding `overlap` (a share), None outside every bin."""
  for lo, hi in bins:
    if lo <= overlap < hi:
      return f'overlap {lo:g}-{min(hi, 1):g}'
  return None


def _cell(results: list[dict]) -> dict:
  s = registration.summarize(results)
  ratios = [r['inliers'] / r['matches'] for r in results if r.get('matches')]
  seconds = [r['seconds'] for r in results if 'seconds' in r]
  judged = [r for r in results if 'registered' in r]
  right = [r['registered'] for r in judged if r['success']]
  wrong = [not r['registered'] for r in judged if not r['success']]
  share = lambda v: float(np.mean(v)) if v else float('nan')
  return {**s, 'inlier_ratio': share(ratios), 'seconds': share(seconds),
          # The verdict: right poses trusted, wrong ones refused, and how many of each.
          'right_trusted': share(right), 'wrong_refused': share(wrong),
          'right': len(right), 'wrong': len(wrong)}


def matrix(results: Mapping[str, list[dict]], info: Mapping[tuple[int, int], dict],
           bins: Sequence[Sequence[float]], overlap_bins: Sequence[Sequence[float]] = ()
           ) -> dict:
  """{row: {(sensor, bin): cell, (sensor, 'all'): ..., ('all', bin): ..., ('all', 'all')}}
  where a cell is `registration.summarize` plus the mean inlier ratio, seconds a pair and
  the verdict's shares (`_cell`). `sensor` is the unit of cloud 2 (cloud 1 is the set's
  reference unit). With `overlap_bins` (shares of cloud 2 on cloud 1 under the true pose,
  pairs.tsv's `overlap`), also ('overlap', overlap bin) cells."""
  out = {}
  for row, per_pair in results.items():
    groups: dict[tuple[str, str], list[dict]] = {}
    for r in per_pair:
      meta = info[r['idx1'], r['idx2']]
      b = distance_bin(meta['distance_m'], bins)
      if b is None:
        continue
      keys = [(meta['sensor2'], b), (meta['sensor2'], 'all'), ('all', b), ('all', 'all')]
      o = overlap_bin(meta['overlap'], overlap_bins) if 'overlap' in meta else None
      if o is not None:
        keys.append(('overlap', o))
      for key in keys:
        groups.setdefault(key, []).append(r)
    out[row] = {key: _cell(rs) for key, rs in groups.items()}
  return out


# What the summary says a row's pairs are, by the set's kind.
INTROS = {
    'cross_sensor': "Cross-sensor registration on {description}: cloud 1 from the set's "
                    'reference unit, cloud 2 from the unit of each column, its standpoint in '
                    'the distance bin, at any yaw.',
    'real_drives': 'Registration of real drives on {description}: two scans of one drive '
                   '(the column), their positions in the distance bin, each pair as driven '
                   'and with cloud 2 turned 180 +- 45 degrees (a revisit from the other '
                   'heading); overlap: the share of cloud 2 within 0.5 m of cloud 1 under '
                   'the true pose.'}


def _missing(row: str, missing: Mapping[str, str]) -> str:
  if row in missing:
    return missing[row]
  return feature_store.missing_reason(row, missing)


def outputs(cells: Mapping[str, dict], rows: Sequence[str], missing: Mapping[str, str],
            sensors: Sequence[str], bins: Sequence[Sequence[float]], workdir: str,
            description: str, name: str, overlap_bins: Sequence[Sequence[float]] = (),
            kind: str = 'cross_sensor') -> str:
  """WORKDIR/{name}.md (success summary by unit, distance and overlap bin with seconds a
  pair and the verdict's shares; one success matrix per row; the detail table) and
  {name}.csv (one line per row x unit x distance cell). `missing`: why a row did not run,
  by checkpoint or row name; kind: `INTROS`'s."""
  bin_labels = [distance_bin(lo, bins) for lo, _ in bins]
  overlap_labels = [overlap_bin(lo, overlap_bins) for lo, _ in overlap_bins]
  ran = [r for r in rows if r in cells]
  pct = lambda c: tables.fmt(100 * c['success_rate'], 1) if c else '-'

  def share(cell, key, count):   # a verdict share (%) with its pair count
    return f'{tables.fmt(100 * cell[key], 1)} ({cell[count]})' if cell and cell[count] else '-'

  header = (['method', 'all'] + list(sensors) + bin_labels + overlap_labels
            + ['s / pair', 'right poses trusted, % (n)', 'wrong poses refused, % (n)'])
  summary = []
  for r in ran:
    everything = cells[r].get(('all', 'all'))
    summary.append([label(r)] + [pct(cells[r].get(key)) for key in
                                 [('all', 'all')] + [(s, 'all') for s in sensors]
                                 + [('all', b) for b in bin_labels]
                                 + [('overlap', o) for o in overlap_labels]]
                   + [tables.fmt(everything['seconds'], 2) if everything else '-',
                      share(everything, 'right_trusted', 'right'),
                      share(everything, 'wrong_refused', 'wrong')])
  summary += [[label(r), f'missing ({_missing(r, missing)})'] for r in rows if r not in cells]
  parts = [INTROS[kind].format(description=description)
           + ' Success (%) = RTE < 2 m and RRE < 5°; s / pair: wall seconds a pair, where '
           'the row times them; the verdict columns: rows that say whether a pose is to be '
           'trusted (`registered`).\n', tables.markdown_table(header, summary)]
  csv_rows = []
  for r in ran:
    parts.append(f'\n{label(r)}: success % (pairs) per unit of cloud 2 x distance\n')
    grid = [[s] + [f'{pct(cells[r].get((s, b)))} ({cells[r][(s, b)]["pairs"]})'
                   if (s, b) in cells[r] else '-' for b in bin_labels] for s in sensors]
    parts.append(tables.markdown_table(['unit'] + bin_labels, grid))
    for s in list(sensors) + ['all']:
      for b in bin_labels + ['all']:
        c = cells[r].get((s, b))
        if c:
          csv_rows.append([r, s, b, c['pairs'], f'{100 * c["success_rate"]:.1f}',
                           tables.fmt(c['rte'], 3), tables.fmt(c['rre'], 3),
                           tables.fmt(c['inlier_ratio'], 4)])
  detail_header = ['method', 'unit', 'distance', 'pairs', 'success (%)', 'RTE (m)', 'RRE (°)',
                   'inlier ratio']
  tables.write_csv(os.path.join(workdir, f'{name}.csv'), detail_header, csv_rows)
  parts.append(f'\nRTE, RRE (successful pairs) and inlier ratio per cell: `{name}.csv`.\n')
  text = '\n'.join(parts)
  with open(os.path.join(workdir, f'{name}.md'), 'w') as f:
    f.write(text)
  return text
