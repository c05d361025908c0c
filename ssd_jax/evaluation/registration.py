"""Tables I and II: keypoints -> descriptors -> NN matches -> RANSAC on every test
pair, summarised as the paper does (docs/method.md §4)."""

from __future__ import annotations

import dataclasses
import json
import time
from typing import Mapping, Sequence, TextIO

import jax
import numpy as np
from tqdm import auto as tqdm

from ssd_jax import geometry
from ssd_jax.infra import distributed, errors
from ssd_jax.data import clean, io
from ssd_jax.evaluation import feature_store, paper, tables
from ssd_jax.evaluation import reference
from ssd_jax.registration import metrics, pair_stages, pipeline, verification
from ssd_jax.registration import options as options_lib


# Rows that register whole clouds, without the project's keypoints and descriptors:
# Open3D's own pipeline (the outside reference), KISS-Matcher + ICP, and the bird's-eye-view
# search alone, its best poses verified (what the descriptor adds to the register
# command's defaults is read against it).
CLOUD_ROWS = {'open3d': 'Open3D ISS + FPFH (paper searches)',
              'bev': 'BEV search alone, verified',
              'kiss_matcher': 'KISS-Matcher + ICP (0.3 m voxels)'}


def _register_whole(row: str, store: feature_store.FeatureStore, pair, seed: int
                    ) -> tuple[np.ndarray, dict]:
  """One of `CLOUD_ROWS` on one pair -> (T_12 [4, 4], {'inliers', 'matches'})."""
  clouds = (store.cloud(pair.cloud1), store.cloud(pair.cloud2))
  if row == 'open3d':
    # ISS as the paper-protocol rows found it: Open3D's same call on the same cloud.
    iss = tuple(store.keypoints(c, 'iss') for c in (pair.cloud1, pair.cloud2))
    t, _, stats = reference.open3d_register(*clouds, seed, 'paper', iss)
    return t, stats
  if row == 'kiss_matcher':
    return reference.kiss_matcher_register(*clouds), {'inliers': 0, 'matches': 0}
  prepared = store.pair(pair.cloud1, pair.cloud2)
  best, refined, _ = verification.verify(prepared.cloud1.target, prepared.cloud2.source,
                                         prepared.bev_poses(feature_store.BEV_CANDIDATES),
                                         memo=prepared.memo)
  return refined[best], {'inliers': 0, 'matches': 0}


def summarize(results: list[dict]) -> dict[str, float]:
  """Table row: RTE / RRE means over successful pairs, success rate and mean trials over
  all pairs."""
  ok = [r for r in results if r['success']]
  mean = lambda key, rows: float(np.mean([r[key] for r in rows])) if rows else float('nan')
  return {'pairs': len(results), 'rte': mean('rte', ok), 'rre': mean('rre', ok),
          'rre_geodesic': mean('rre_geodesic', ok),
          'success_rate': len(ok) / max(len(results), 1),
          'trials': mean('trials', results)}


def failed(error: str) -> dict:
  """The result fields of a pair a row could not register (`error`: why, one line)."""
  return {'trials': 0, 'inliers': 0, 'matches': 0, 'rte': float('inf'), 'rre': float('inf'),
          'rre_geodesic': float('inf'), 'success': False, 'error': error}


def register_pairs(pairs: Sequence, rows: Sequence[str], store: feature_store.FeatureStore, *,
                   seed: int = 0, inlier_threshold: float = 1.0, confidence: float = 0.99,
                   max_trials: int = 10_000, log: TextIO | None = None,
                   progress: bool = True, desc: str = 'registration',
                   sampling: str = 'auto') -> dict[str, list[dict]]:
  """Register every pair with every row -> {row: [per-pair result]}.

  pairs: `registration_sets.RegistrationPair`s, T_12 between the clouds as `store` gives
  them. A row of the register command (`feature_store.command_options`: every row that
  verifies its poses) runs its path, `pipeline.Registrar` on the pairs' files with the
  command's RANSAC settings seeded with `seed`, and gives its verdict
  (`verdict.Verdict.to_json`) and the seconds the pair cost; a row of the paper's
  protocol registers the store's features (`pair_stages.estimate` with `inlier_threshold`,
  `confidence`, `max_trials` and `sampling`) and a `CLOUD_ROWS` row the store's clouds,
  pair n's RANSAC seeded with seed * 1,000,003 + n, so that its numbers do not depend on
  the other rows. Each result holds RTE, RRE (Euler sum, geodesic), success, trials,
  inliers and matches (a pair with fewer than 3 keypoints in a cloud fails, with its
  `error`). With `log`, one JSON line per pair and row is written to it. Over several
  processes each registers its share of the pairs (`distributed.map_items`) and every
  process returns all results; the log is written when they are gathered.
  """
  if sampling not in options_lib.SAMPLINGS:
    raise errors.UserError(f'sampling must be one of {options_lib.SAMPLINGS}, got {sampling!r}')
  one_process = jax.process_count() == 1
  described = [row for row in rows if row not in CLOUD_ROWS]
  store.describe_fpfh_together(described)
  registrars = {}
  for row in described:
    command = feature_store.command_options(row, store.models)
    if command is not None:
      options, model = command
      registrars[row] = pipeline.Registrar(clean.read_metres, model=model,
                                           options=dataclasses.replace(options, seed=seed),
                                           say=lambda line: None)

  def register(n: int, pair) -> list[dict]:
    out = []
    for row in rows:
      res = {'row': row, 'sequence': pair.sequence, 'idx1': pair.idx1, 'idx2': pair.idx2}
      t0 = time.perf_counter()
      try:
        if row in CLOUD_ROWS:
          t, stats = _register_whole(row, store, pair, seed * 1_000_003 + n)
          res.update(trials=0, **stats, seconds=time.perf_counter() - t0)
        else:
          if row in registrars:
            reg, _, _ = registrars[row].register(str(pair.cloud1), str(pair.cloud2))
            reg.transform = store.in_levelled_frame(pair.cloud1, pair.cloud2, reg.transform)
            # the command's verdict, and what the pair cost it
            res.update(seconds=time.perf_counter() - t0, **reg.verdict.to_json())
          else:
            reg = pair_stages.estimate(
                store.features(pair.cloud1, row), store.features(pair.cloud2, row),
                seed * 1_000_003 + n, inlier_threshold, confidence, max_trials,
                feature_store.row_estimator(row), sampling=sampling)
          t = reg.transform
          res.update(trials=reg.trials, inliers=int(reg.inliers.sum()),
                     matches=len(reg.inliers), levels=reg.levels_tried)
      except (io.CloudFileError, clean.CloudDataError):
        raise   # a damaged test file stops the benchmark, named
      except ValueError as e:   # too few keypoints, a cloud no keypoints register (too small,
        # flat): a failed pair, not a failed benchmark
        res = {k: res[k] for k in ('row', 'sequence', 'idx1', 'idx2')} | failed(str(e))
      else:
        res.update(metrics.registration_errors(pair.transform, t))
      out.append(res)
      if log is not None and one_process:   # as it goes: a stopped run keeps its pairs
        log.write(json.dumps(res) + '\n')
    return out

  per_pair = distributed.map_items(
      register, pairs, lambda ns: tqdm.tqdm(ns, desc=desc, unit='pair', disable=not progress))
  results = {row: [] for row in rows}
  for pair_results in per_pair:
    for res in pair_results:
      results[res['row']].append(res)
      if log is not None and not one_process:
        log.write(json.dumps(res) + '\n')
  return results


HEADER = ('keypoints + descriptor', 'pairs', 'RTE (m)', 'RRE (°)', 'RRE geodesic (°)',
          'success (%)', 'avg #iter')


def registration_table(results: Mapping[str, list[dict]], rows: Sequence[str],
                       missing: Mapping[str, str], paper_set: str = 'none'):
  """-> (header, table rows) with the paper's row beside each (`paper_set`:
  oxford | kitti | none); rows that could not run say why."""
  ref_rows = paper.REGISTRATION.get(paper_set, {})
  header = list(HEADER) + [f'paper ({paper_set}): RTE / RRE / success / #iter']
  table = []
  for row in rows:
    ref = ref_rows.get(row)
    ref = ' / '.join(str(v) for v in ref) if ref else '-'
    if row in results:
      s = summarize(results[row])
      table.append([feature_store.row_label(row), s['pairs'], tables.fmt(s['rte'], 3),
                    tables.fmt(s['rre'], 3), tables.fmt(s['rre_geodesic'], 3),
                    tables.fmt(100 * s['success_rate']), f'{s["trials"]:.0f}', ref])
    else:
      table.append([feature_store.row_label(row), 'missing', '-', '-', '-', '-', '-',
                    f'{ref} ({feature_store.missing_reason(row, missing)})'])
  return header, table


YAW_BINS = ((0, 45), (45, 90), (90, 135), (135, 180))   # |relative yaw|, degrees


def relative_yaw_deg(transform: np.ndarray) -> float:
  """|rotation about z| of T [4, 4] in degrees, in [0, 180]."""
  return float(abs(geometry.yaw_deg(np.asarray(transform))))


def yaw_bin(yaw: float) -> int:
  """Index into YAW_BINS of an absolute yaw in [0, 180] degrees."""
  return min(int(yaw // 45), len(YAW_BINS) - 1)


def _yaw_bins(pairs: Sequence) -> np.ndarray:
  return np.array([yaw_bin(relative_yaw_deg(p.transform)) for p in pairs], int)


def success_by_yaw(pairs: Sequence, results: Sequence[dict]) -> list[tuple[int, float]]:
  """Per bin of YAW_BINS: (pairs in the bin, success in percent; NaN for an empty bin)."""
  bins = _yaw_bins(pairs)
  ok = np.array([r['success'] for r in results], bool)
  masks = [bins == b for b in range(len(YAW_BINS))]
  return [(int(m.sum()), 100 * float(ok[m].mean()) if m.any() else float('nan')) for m in masks]


def yaw_table(pairs: Sequence, results: Mapping[str, list[dict]], rows: Sequence[str]):
  """-> (header, table rows): each row's success per bin of the pairs' relative yaw, the
  bin's pair count in the header; rows that did not run are left out."""
  counts = np.bincount(_yaw_bins(pairs), minlength=len(YAW_BINS))
  header = ['keypoints + descriptor'] + [f'{lo}-{hi}° ({n} pairs)'
                                         for (lo, hi), n in zip(YAW_BINS, counts)]
  table = [[feature_store.row_label(row)] + [tables.fmt(v) if n else '-'
                                             for n, v in success_by_yaw(pairs, results[row])]
           for row in rows if row in results]
  return header, table
