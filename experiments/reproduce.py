r"""Reproduce every table and figure of the paper that the data under a root allows.

    python -m experiments.reproduce --data_root=DIR --workdir=OUT [--config=configs/reproduce.py]

Runs, as the data allows: Table I (Oxford registration), Table II (KITTI
registration), Fig. 4 (precision), Table III (descriptor matching, all pairs and
ISS-filtered), Fig. 3 (ISS vs learned keypoints) and the registration figures
(Figs. 5-6). Writes every table (Markdown + CSV), figure and per-pair log into
OUT, and OUT/report.md with the paper's numbers beside and a list of what was
skipped and why. Every number is recomputed from the data and checkpoints.
"""

import datetime
import sys
import time
from pathlib import Path

from absl import app
from absl import flags
import ml_collections

from ssd_jax import cli, viz
from ssd_jax.data import benchmarks, io
from ssd_jax.evaluation import feature_store, fingerprint, runs
from ssd_jax.logging_utils import quiet_libraries
from ssd_jax.registration import pipeline

FLAGS = flags.FLAGS
flags.DEFINE_string('data_root', None, 'Folder holding test sets (see configs/reproduce.py).')
flags.DEFINE_string('workdir', None, 'Output folder for report.md, tables and figures.')
cli.define_config_file('config', 'configs/reproduce.py', 'Reproduction config.')
flags.mark_flags_as_required(['data_root', 'workdir'])

REPRODUCIBILITY = (
    'The same command on the same machine writes the same numbers (every stage is '
    'seeded). Across machines, a short hash of each stage\'s output below tells where two '
    'reports part: the first differing row is the stage to look at. The generated data, '
    'ISS keypoints and FPFH do not depend on the thread count or the CPU\'s vector '
    'instructions; the learned descriptors and RANSAC fits do not either between AVX2 and '
    'AVX-512, but differ in their last bits on a CPU without AVX, and training there gives '
    'other weights and other "this run" rows: docs/reproduce.md gives the measured spread.')

TITLES = {'oxford': 'Table I: registration on Oxford-style pairs',
          'kitti': 'Table II: registration on KITTI-style pairs'}


def find_sets(root: Path, candidates) -> tuple[dict, list[str]]:
  """{'oxford'|'kitti': [pairs], 'clusters': folder} for what exists, and skip notes."""
  found, skipped = {}, []
  for name in ('oxford', 'kitti'):
    tried = [root / c for c in candidates[name]]
    for path in tried:
      if path.is_dir():
        try:
          found[name] = (path, benchmarks.read_registration_set(path))
          break
        except io.CloudFileError as e:
          skipped.append(f'{name}: {path} is not a usable test set ({e})')
    else:
      skipped.append(f'{name}: none of {", ".join(str(p) for p in tried)} holds a test set')
  tried = [root / c for c in candidates['clusters']]
  hits = [p for p in tried if (p / 'filenames.txt').is_file()]
  if hits:
    found['clusters'] = hits[0]
  else:
    skipped.append(f'clusters: no filenames.txt in {", ".join(str(p) for p in tried)}; '
                   'Table III skipped')
  return found, skipped


def keypoint_figure(config, store, missing, cloud_path, out_dir) -> tuple[str, list[str]]:
  """Fig. 3 on one cloud: each available keypoint source's keypoints as red dots."""
  points = store.cloud(cloud_path)
  shown, skipped = {}, []
  for source in config.figures.keypoint_sources:
    name = feature_store.NAMES.get(source, source)
    if source in missing:
      skipped.append(f'Fig. 3 {name} keypoints: {missing[source]}')
      continue
    shown[f'{name} keypoints'] = points[store.keypoints(cloud_path, source)]
  viz.plot_keypoints(points, shown, out_dir / 'fig3_keypoints.png')
  text = (f'Keypoints on {cloud_path} (top view, red dots).\n\n![keypoints](fig3_keypoints.png)\n')
  return text, skipped


def registration_figures(config, store, missing, name, pairs, out_dir) -> tuple[str, list[str]]:
  """Figs. 5-6: the first pair of a set registered with each figure row."""
  pair, text, skipped = pairs[0], [], []
  for row in config.figures.registration_rows:
    if set(feature_store.split_row(row)) & set(missing):
      skipped.append(f'{name} registration figure {feature_store.row_label(row)}: '
                     f'{feature_store.missing_reason(row, missing)}')
      continue
    f1, f2 = store.features(pair.cloud1, row), store.features(pair.cloud2, row)
    reg = pipeline.estimate(f1, f2, seed=config.seed * 1_000_003,
                            inlier_threshold=config.inlier_threshold,
                            confidence=config.confidence, max_trials=config.max_trials)
    file = f'registration_{name}_{row.replace("+", "_")}.png'
    viz.plot_registration(store.cloud(pair.cloud1), store.cloud(pair.cloud2), f1.xyz,
                          f2.xyz[reg.matches[:, 1]], reg.inliers, out_dir / file,
                          title=f'{feature_store.row_label(row)}: {int(reg.inliers.sum())} inliers '
                                f'of {len(reg.inliers)} matches')
    text.append(f'{feature_store.row_label(row)}, pair {pair.idx1}/{pair.idx2} '
                f'({pair.sequence}):\n\n![{row}]({file})\n')
  return '\n'.join(text), skipped


class Stages:
  """Numbered stage headers on stderr and per-stage wall times for the report."""

  def __init__(self, total: int):
    self.total, self.n, self.seconds = total, 0, {}

  def run(self, title: str, fn, *args):
    self.n += 1
    print(f'[{self.n}/{self.total}] {title}', file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    out = fn(*args)
    self.seconds[title] = time.perf_counter() - t0
    return out


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  quiet_libraries()
  root, out_dir = Path(FLAGS.data_root), Path(FLAGS.workdir)
  if not root.is_dir():
    raise SystemExit(f'error: --data_root {root} is not a directory')
  try:   # bad rows, unreadable or degenerate clouds: one line, no traceback
    reproduce(FLAGS.config, root, out_dir)
  except ValueError as e:
    raise SystemExit(f'error: {e}') from None
  print(f'wrote {out_dir / "report.md"}')


def reproduce(config, root: Path, out_dir: Path) -> None:
  """Every evaluation the data under `root` allows; writes out_dir/report.md."""
  figure_rows = [f'{src}+fpfh' for src in (*config.figures.keypoint_sources,
                                            *config.keypoint_sources)]
  store, missing = runs.open_store(
      config, list(config.rows) + list(config.figures.registration_rows) + figure_rows)
  found, skipped = find_sets(root, config.sets)
  if not found:
    raise SystemExit(f'error: nothing to evaluate under {root}:\n  ' + '\n  '.join(skipped))
  out_dir.mkdir(parents=True, exist_ok=True)
  reg_sets = [n for n in ('oxford', 'kitti') if n in found]
  prec_sets = [n for n in config.precision_sets if n in found]
  stages = Stages(2 * len(reg_sets) + len(prec_sets) + ('clusters' in found) + bool(reg_sets))
  sections = []
  for name in reg_sets:
    path, pairs = found[name]
    if config.max_pairs:
      pairs = pairs[:config.max_pairs]
      found[name] = (path, pairs)
    text = stages.run(TITLES[name], runs.run_registration, config, pairs, store, missing,
                      str(out_dir), name, f'{path} ({len(pairs)} pairs)', f'table_{name}')
    sections.append((TITLES[name], text))
  for name in prec_sets:
    path, pairs = found[name]
    title = f'Fig. 4: precision on {name}-style pairs'
    text = stages.run(title, runs.run_precision, config, pairs, store, missing, str(out_dir),
                      f'{path} ({len(pairs)} pairs)', f'fig4_precision_{name}')
    sections.append((title, text))
  for name in reg_sets:
    path, pairs = found[name]
    title = f'Keypoint repeatability on {name}-style pairs'
    text = stages.run(title, runs.run_repeatability, config, pairs, store, missing,
                      str(out_dir), f'{path} ({len(pairs)} pairs)', f'repeatability_{name}')
    sections.append((title, text))
  if 'clusters' in found:
    dm = ml_collections.ConfigDict(config.descriptor_matching.to_dict())
    dm.checkpoints, dm.fpfh_max_nn = config.checkpoints, config.fpfh_max_nn
    title = 'Table III: descriptor matching'
    sections.append((title, stages.run(title, runs.run_descriptor_matching, dm,
                                       found['clusters'], str(out_dir))))
  if reg_sets:
    def figures():
      first = found[reg_sets[0]][1][0].cloud1
      text, skip = keypoint_figure(config, store, missing, first, out_dir)
      parts = [('Fig. 3: ISS and learned keypoints', text)]
      for name in reg_sets:
        t, s = registration_figures(config, store, missing, name, found[name][1], out_dir)
        skip += s
        if t:
          parts.append((f'Registration example ({name})', t))
      return parts, skip
    parts, skip = stages.run('Figures 3, 5 and 6', figures)
    sections += parts
    skipped += skip
  write_report(out_dir, root, config, store, missing, sections, skipped, stages.seconds)


def write_report(out_dir, root, config, store, missing, sections, skipped, seconds):
  lines = [
      '# ssd_jax: reproduction report', '',
      f'Generated {datetime.datetime.now().isoformat(timespec="seconds")} by',
      f'`python -m experiments.reproduce --data_root={root} --workdir={out_dir}`',
      f'with the config below. Every number here was computed by this run; the paper\'s '
      'numbers are shown beside for comparison.', '', '## Checkpoints', '']
  for name, path in sorted(config.checkpoints.items()):
    model = store.models.get(name)
    lines.append(f'- {feature_store.NAMES.get(name, name)}: `{path}` ' +
                 (f'(step {model.step})' if model is not None else
                  f'**missing**: {missing.get(name, "not used by any row")}'))
  lines += ['', '## Skipped', '']
  lines += [f'- {s}' for s in skipped] or ['- nothing']
  for title, text in sections:
    lines += ['', f'## {title}', '', text.strip()]
  stages = store.fingerprints()
  for log in sorted(out_dir.glob('table_*_pairs.jsonl')):
    table = log.name[len('table_'):-len('_pairs.jsonl')]
    stages.update({f'registration: {table}, {row}': d
                   for row, d in fingerprint.registration_digests(log).items()})
  lines += ['', '## Reproducibility', '', REPRODUCIBILITY, '',
            fingerprint.markdown(stages, fingerprint.environment())]
  lines += ['', '## Time', '', '| stage | s |', '|---|---|']
  lines += [f'| {k} | {v:.1f} |' for k, v in seconds.items()]
  lines += [f'| (within these) {k} | {v:.1f} |' for k, v in sorted(store.seconds.items())]
  lines += ['', '## Config', '', '```', str(config).strip(), '```', '']
  (out_dir / 'report.md').write_text('\n'.join(lines))


if __name__ == '__main__':
  cli.run(main)
