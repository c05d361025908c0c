"""Named evaluators and the one loop that runs the evaluations a config lists.

A config names its evaluations under `config.evals` (big_vision's pattern), each a
section `{type: <evaluator>, <its settings>}`:

    registration         Tables I / II: keypoints -> descriptors -> NN matches -> RANSAC
    precision            Fig. 4: descriptor nearest neighbours within x of the truth
    repeatability        keypoints found again within a radius after the true alignment
    descriptor_matching  Table III: FPR at 95 % recall on cluster pairs
    figures              Fig. 3 (keypoints) and Figs. 5-6 (registration examples)
    cross_sensor         registration as a sensor x distance matrix, with Open3D's pipeline

Shared settings (checkpoints, rows, RANSAC, seeds): configs/evals/evaluation.py. Data
paths are tried in order, relative to `config.data_root`; an evaluation without its data
is skipped and the report says why. `evaluate` runs them in the order of `TYPES`, writes
each one's tables and figures under its name, and OUT/report.md with them all, the
checkpoints, what was skipped, a hash and the time per stage, and the config.
"""

from __future__ import annotations

import collections
import dataclasses
import datetime
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable, Sequence

import jax
import ml_collections

from ssd_jax import viz
from ssd_jax.infra import distributed, errors
from ssd_jax.data import clusters, io, registration_sets
from ssd_jax.evaluation import (cross_sensor, descriptor_matching, feature_store, fingerprint,
                                precision, registration, repeatability, report)
from ssd_jax.evaluation import reference
from ssd_jax.registration import pair_stages

REPRODUCIBILITY = (
    'The same command on the same machine writes the same numbers (every stage is '
    'seeded). Across machines, a short hash of each stage\'s output below tells where two '
    'reports part: the first differing row is the stage to look at. The generated data, '
    'ISS keypoints and FPFH do not depend on the thread count or the CPU\'s vector '
    'instructions; the learned descriptors and RANSAC fits do not either between AVX2 and '
    'AVX-512, but differ in their last bits on a CPU without AVX, and training there gives '
    'other weights and other "this run" rows: docs/reproduce.md gives the measured spread.')


class Unavailable(Exception):
  """The data an evaluation needs is not under the data root: skip it, say why."""


@dataclasses.dataclass
class Section:
  title: str
  text: str
  skipped: list[str] = dataclasses.field(default_factory=list)


@dataclasses.dataclass
class Context:
  """What every evaluator gets besides its own settings `ev`."""
  config: ml_collections.ConfigDict     # the whole config (shared settings at the top)
  store: feature_store.FeatureStore
  missing: dict[str, str]               # checkpoint name -> why it is not loaded
  workdir: Path
  data_root: Path

  def find(self, candidates, read: Callable, what: str):
    """The first of `candidates` (a path or a tuple of them, relative to the data root)
    that exists -> (path, read(path)); Unavailable naming every path tried otherwise."""
    tried, reasons = [], []
    for c in (candidates,) if isinstance(candidates, str) else tuple(candidates):
      path = self.data_root / c
      tried.append(str(path))
      if not path.exists():
        continue
      try:
        return path, read(path)
      except io.CloudFileError as e:
        reasons.append(f'{path} is not a usable {what} ({e})')
    if reasons:
      raise Unavailable('; '.join(reasons))
    raise Unavailable(f'no {what} at {", ".join(tried)}')

  def pairs(self, candidates):
    path, pairs = self.find(candidates, registration_sets.read_registration_set, 'registration set')
    max_pairs = self.config.max_pairs
    pairs = pairs[:max_pairs] if max_pairs else pairs
    return self.store.in_levelled_frames(pairs), f'{path} ({len(pairs)} pairs)'


def _registration(name, ev, ctx: Context) -> Section:
  pairs, description = ctx.pairs(ev.dataset)
  cfg, rows = ctx.config, list(ctx.config.rows)
  with open(ctx.workdir / f'{name}_pairs.jsonl', 'w') as log:
    results = registration.register_pairs(
        pairs, feature_store.runnable_rows(rows, ctx.missing), ctx.store, seed=cfg.seed,
        inlier_threshold=cfg.inlier_threshold, confidence=cfg.confidence,
        max_trials=cfg.max_trials, log=log, desc=name,
        sampling=cfg.get('sampling', 'auto'))
  return Section(ev.title, report.registration_outputs(
      pairs, results, rows, ctx.missing, str(ctx.workdir), ev.paper, description, name))


def _cross_sensor(name, ev, ctx: Context) -> Section:
  read = lambda path: (registration_sets.read_registration_set(path),
                       registration_sets.read_pair_info(path))
  path, (pairs, info) = ctx.find(ev.dataset, read, 'cross-sensor set')
  pairs = pairs[:ctx.config.max_pairs] if ctx.config.max_pairs else pairs
  pairs = ctx.store.in_levelled_frames(pairs)
  cfg, rows = ctx.config, list(ev.rows)
  missing = dict(ctx.missing)
  if 'kiss_matcher' in rows and reference.kiss_matcher is None:
    missing['kiss_matcher'] = reference.KISS_MISSING
  described = feature_store.runnable_rows(
      [r for r in rows if r not in registration.CLOUD_ROWS], ctx.missing)
  runnable = [r for r in rows if r in described
              or (r in registration.CLOUD_ROWS and r not in missing)]
  with open(ctx.workdir / f'{name}_pairs.jsonl', 'w') as log:
    results = registration.register_pairs(
        pairs, runnable, ctx.store, seed=cfg.seed, inlier_threshold=cfg.inlier_threshold,
        confidence=cfg.confidence, max_trials=cfg.max_trials, log=log, desc=name,
        sampling=cfg.get('sampling', 'auto'))
  units = list(dict.fromkeys(info[p.idx1, p.idx2]['sensor2'] for p in pairs))
  overlap_bins = ev.get('overlap_bins', ())
  cells = cross_sensor.matrix(results, info, ev.distance_bins, overlap_bins)
  return Section(ev.title, cross_sensor.outputs(
      cells, rows, missing, units, ev.distance_bins, str(ctx.workdir),
      f'{path} ({len(pairs)} pairs)', name, overlap_bins, ev.get('kind', 'cross_sensor')))


def _precision(name, ev, ctx: Context) -> Section:
  pairs, description = ctx.pairs(ev.dataset)
  rows = list(ctx.config.rows)
  results = precision.evaluate_precision(pairs, feature_store.runnable_rows(rows, ctx.missing),
                                         ctx.store, overlap_radius=ev.overlap_radius, desc=name)
  return Section(ev.title, report.precision_outputs(
      results, rows, ctx.missing, str(ctx.workdir), ev.read_at, description, name))


def _repeatability(name, ev, ctx: Context) -> Section:
  pairs, description = ctx.pairs(ev.dataset)
  sources = [s for s in ev.keypoint_sources if s not in ctx.missing]
  results = repeatability.evaluate_repeatability(pairs, sources, ctx.store, ev.radius)
  return Section(ev.title, report.repeatability_outputs(
      results, list(ev.keypoint_sources), ctx.missing, str(ctx.workdir), description,
      ev.radius, name))


def _descriptor_matching(name, ev, ctx: Context) -> Section:
  folder, pairs = ctx.find(ev.clusters, clusters.read_cluster_pairs, 'cluster set')
  pairs = pairs[:ev.max_pairs] if ev.max_pairs else pairs
  names = [n for n in ev.descriptors if n not in ctx.missing]
  descriptors = {n: (None if n in feature_store.BUILTIN_DESCRIPTORS else ctx.store.models[n])
                 for n in names}
  distances, iss_distance = descriptor_matching.describe_pairs(
      pairs, descriptors, radius=ev.radius, fpfh_max_nn=ctx.config.fpfh_max_nn)
  labels = [p.label for p in pairs]
  descriptor_matching.save_distances(str(ctx.workdir / f'{name}_distances.npz'), labels,
                                     distances, iss_distance)
  missing = {n: ctx.missing[n] for n in ev.descriptors if n in ctx.missing}
  return Section(ev.title, report.descriptor_matching_outputs(
      distances, labels, iss_distance, tuple(ev.r_th), missing, str(ctx.workdir),
      f'{folder} ({len(pairs)} pairs)', recall=ev.recall, name=name))


def _figures(name, ev, ctx: Context) -> Section:
  """Fig. 3 on the first cloud of the first set found; Figs. 5-6 on each set's first pair."""
  found, skipped = {}, []
  for set_name, candidates in ev.sets.items():
    try:
      found[set_name] = ctx.pairs(candidates)[0]
    except Unavailable as e:
      skipped.append(f'{ev.title} ({set_name}): {e}')
  if not found:
    raise Unavailable('; '.join(skipped))
  parts = [_keypoint_figure(name, ev, ctx, next(iter(found.values()))[0].cloud1, skipped)]
  for set_name, pairs in found.items():
    parts += _registration_figures(name, ev, ctx, set_name, pairs[0], skipped)
  return Section(ev.title, '\n'.join(parts), skipped)


def _keypoint_figure(name, ev, ctx: Context, cloud_path, skipped: list[str]) -> str:
  points, shown = ctx.store.cloud(cloud_path), {}
  for source in ev.keypoint_sources:
    label = feature_store.NAMES.get(source, source)
    if source in ctx.missing:
      skipped.append(f'Fig. 3 {label} keypoints: {ctx.missing[source]}')
      continue
    shown[f'{label} keypoints'] = points[ctx.store.keypoints(cloud_path, source)]
  file = f'{name}_keypoints.png'
  viz.plot_keypoints(points, shown, ctx.workdir / file)
  return f'Keypoints on {cloud_path} (top view, red dots).\n\n![keypoints]({file})\n'


def _registration_figures(name, ev, ctx: Context, set_name, pair, skipped) -> list[str]:
  cfg, parts = ctx.config, []
  for row in ev.registration_rows:
    label = feature_store.row_label(row)
    if set(feature_store.split_row(row)) & set(ctx.missing):
      skipped.append(f'{set_name} registration figure {label}: '
                     f'{feature_store.missing_reason(row, ctx.missing)}')
      continue
    f1, f2 = ctx.store.features(pair.cloud1, row), ctx.store.features(pair.cloud2, row)
    reg = pair_stages.estimate(f1, f2, seed=cfg.seed * 1_000_003,
                               inlier_threshold=cfg.inlier_threshold, confidence=cfg.confidence,
                               max_trials=cfg.max_trials)
    file = f'{name}_{set_name}_{row.replace("+", "_")}.png'
    viz.plot_registration(ctx.store.cloud(pair.cloud1), ctx.store.cloud(pair.cloud2),
                          f1.xyz[reg.matches[:, 0]], f2.xyz[reg.matches[:, 1]], reg.inliers,
                          ctx.workdir / file,
                          title=f'{label}: {int(reg.inliers.sum())} inliers of '
                                f'{len(reg.inliers)} matches')
    parts.append(f'{set_name}, {label}, pair {pair.idx1}/{pair.idx2} ({pair.sequence}):\n\n'
                 f'![{row}]({file})\n')
  return parts


@dataclasses.dataclass(frozen=True)
class Evaluator:
  run: Callable[[str, ml_collections.ConfigDict, Context], Section]
  # (config, ev) -> the keypoint x descriptor rows it computes (which checkpoints to load)
  rows: Callable[[ml_collections.ConfigDict, ml_collections.ConfigDict], list[str]]


def _config_rows(config, ev):
  del ev
  return list(config.rows)


EVALUATORS = {
    'registration': Evaluator(_registration, _config_rows),
    'precision': Evaluator(_precision, _config_rows),
    'repeatability': Evaluator(_repeatability,
                               lambda config, ev: [f'{s}+fpfh' for s in ev.keypoint_sources]),
    'descriptor_matching': Evaluator(_descriptor_matching,
                                     lambda config, ev: [f'iss+{d}' for d in ev.descriptors]),
    'figures': Evaluator(_figures, lambda config, ev: list(ev.registration_rows) + [
        f'{s}+fpfh' for s in ev.keypoint_sources]),
    'cross_sensor': Evaluator(_cross_sensor, lambda config, ev: [
        r for r in ev.rows if r not in registration.CLOUD_ROWS]),
}
TYPES = tuple(EVALUATORS)


def ordered_evals(config: ml_collections.ConfigDict) -> list[tuple[str, ml_collections.ConfigDict]]:
  """config.evals as [(name, section)] in run order; an unknown type is a clear error."""
  evals = list(config.evals.items())
  if not evals:
    raise errors.UserError('config.evals is empty: name at least one evaluation')
  for name, ev in evals:
    if ev.get('type') not in EVALUATORS:
      raise errors.UserError(f'evals.{name}.type must be one of {", ".join(TYPES)}, '
                             f'got {ev.get("type")!r}')
  return sorted(evals, key=lambda e: (TYPES.index(e[1].type), e[0]))


def rows_needed(config: ml_collections.ConfigDict) -> list[str]:
  """Every keypoint x descriptor row the evaluations use (for loading checkpoints)."""
  rows = [r for _, ev in ordered_evals(config) for r in EVALUATORS[ev.type].rows(config, ev)]
  return list(dict.fromkeys(rows))


def evaluate(config: ml_collections.ConfigDict, workdir: str | os.PathLike,
             command: str = '', log: Callable[[str], None] | None = None) -> tuple[Path, str]:
  """Run every evaluation of config.evals whose data exists.

  Writes each one's outputs and report.md into `workdir`; `command` is quoted in the
  report. Returns (report path, the Markdown of the evaluations that ran). Raises
  ValueError when none could run (the message says why for each) or on bad input.

  Over several processes (`distributed`) every process runs this with the same config:
  each evaluation splits its pairs over them and gathers the results, so all build the
  same report, and only process 0 keeps its files (the others write to a scratch folder).
  """
  if not distributed.is_main():
    with tempfile.TemporaryDirectory() as scratch:
      _, text = _evaluate(config, Path(scratch), command, log=lambda s: None)
    return Path(workdir) / 'report.md', text
  return _evaluate(config, Path(workdir), command,
                   log or (lambda s: print(s, file=sys.stderr, flush=True)))


def _evaluate(config: ml_collections.ConfigDict, workdir: Path, command: str,
              log: Callable[[str], None]) -> tuple[Path, str]:
  evals = ordered_evals(config)
  models, missing = feature_store.load_models(config.checkpoints,
                                              feature_store.model_names(rows_needed(config)))
  # Configs written before an option existed get the store's default for it.
  optional = {k: config[k] for k in ('level', 'num_keypoints') if k in config}
  store = feature_store.FeatureStore(models, config.seed, config.fpfh_max_nn, **optional)
  workdir.mkdir(parents=True, exist_ok=True)
  ctx = Context(config, store, missing, workdir, Path(config.data_root or '.'))
  sections, skipped, seconds, ran = [], [], {}, []
  for n, (name, ev) in enumerate(evals, 1):
    log(f'[{n}/{len(evals)}] {ev.title}')
    t0 = time.perf_counter()
    try:
      section = EVALUATORS[ev.type].run(name, ev, ctx)
    except Unavailable as e:
      skipped.append(f'{ev.title}: {e}')
      continue
    seconds[ev.title] = time.perf_counter() - t0
    sections.append(section)
    ran.append((name, ev.type))
    skipped += section.skipped
  if not sections:
    raise errors.UserError(f'nothing to evaluate under {ctx.data_root}: ' + '; '.join(skipped))
  path = workdir / 'report.md'
  path.write_text(_report(config, ctx, sections, skipped, seconds,
                          _keypoint_sources(config, ran),
                          [name for name, kind in ran if kind == 'registration'], command))
  return path, '\n\n'.join(f'## {s.title}\n\n{s.text.strip()}' for s in sections)


def _keypoint_sources(config, ran: Sequence[tuple[str, str]]) -> set[str]:
  """The keypoint sources of the rows the evaluations that ran computed."""
  return {feature_store.split_row(row)[0] for name, kind in ran
          for row in EVALUATORS[kind].rows(config, config.evals[name])}


def _report(config, ctx: Context, sections: Sequence[Section], skipped: Sequence[str],
            seconds: dict, keypoint_sources: set[str], registration_names: Sequence[str],
            command: str) -> str:
  lines = ['# ssd_jax: evaluation report', '',
           f'Generated {datetime.datetime.now().isoformat(timespec="seconds")} by',
           f'`{command or "ssd_jax.evaluation.evaluators.evaluate"}`',
           'with the config below. Every number here was computed by this run; the paper\'s '
           'numbers are shown beside for comparison.', '', '## Checkpoints', '']
  for name, path in sorted(config.checkpoints.items()):
    model = ctx.store.models.get(name)
    if model is not None:
      state = f'(step {model.step})'
    elif name in ctx.missing:
      state = f'**missing**: {ctx.missing[name]}'
    else:
      state = 'not loaded: no row uses it'
    lines.append(f'- {feature_store.NAMES.get(name, name)}: `{path}` {state}')
  detectors = sorted(set(keypoint_sources) & set(feature_store.DETECTORS))
  if detectors:
    lines += ['', 'Keypoint rows named after a checkpoint use its detector:', '']
    lines += [f'- {feature_store.NAMES.get(name, name)} kpt: {feature_store.DETECTORS[name]}.'
              for name in detectors]
  lines += ['', '## Skipped', '']
  lines += [f'- {s}' for s in skipped] or ['- nothing']
  for s in sections:
    lines += ['', f'## {s.title}', '', s.text.strip()]
  # Over several processes each store holds its share of the files.
  file_digests, store_seconds = {}, collections.Counter()
  for digests, secs in distributed.gather((ctx.store.file_digests(), dict(ctx.store.seconds))):
    for stage, files in digests.items():
      file_digests.setdefault(stage, {}).update(files)
    store_seconds.update(secs)
  stages = ctx.store.fingerprints(file_digests)
  for name in registration_names:
    digests = fingerprint.registration_digests(ctx.workdir / f'{name}_pairs.jsonl')
    stages.update({f'registration: {name}, {row}': d for row, d in digests.items()})
  lines += ['', '## Reproducibility', '', REPRODUCIBILITY, '',
            fingerprint.markdown(stages, fingerprint.environment())]
  lines += ['', '## Time', '', '| stage | s |', '|---|---|']
  lines += [f'| {k} | {v:.1f} |' for k, v in seconds.items()]
  within = ('(within these, summed over processes)' if jax.process_count() > 1
            else '(within these)')
  lines += [f'| {within} {k} | {v:.1f} |' for k, v in sorted(store_seconds.items())]
  lines += ['', '## Config', '', '```', str(config).strip(), '```', '']
  return '\n'.join(lines)
