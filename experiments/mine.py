r"""Mine training pairs from a folder of unlabeled scans in capture order: each scan with
the scans `--gaps` after it, registered by the classical path (FPFH, RANSAC, the BEV
search, verification by ICP) and kept only where the pose is confident and closes loops
(`ssd_jax.adaptation.mining`). No pose is read.

    python -m experiments.mine --scans=data_cache/scans_vlp16 --out=runs/mined.csv \
        [--gaps=1,2,4,8] [--poses=data_cache/scans_vlp16_poses.txt] [--workers=N]

OUT is a CSV of every candidate pair (T_12, verified fitness, confident, kept, why not);
a rerun registers only the pairs it does not hold yet. `--poses` (ground truth in KITTI's
layout, one line per scan in sorted order; only read after mining) prints the precision
of the kept labels. `experiments.adapt --pairs=OUT` trains on the kept pairs.
"""

import functools

from absl import app
from absl import flags
import numpy as np
from tqdm import auto as tqdm

from ssd_jax.infra import cli, errors
from ssd_jax.data import clean, io, kitti, mined_pairs
from ssd_jax.infra.logging_utils import quiet_libraries
from ssd_jax.adaptation import mining

FLAGS = flags.FLAGS
flags.DEFINE_string('scans', None, 'Folder (or index .txt) of unlabeled scans, in capture '
                    'order by name.')
flags.DEFINE_string('out', None, 'CSV of the mined pairs (a rerun resumes it).')
flags.DEFINE_list('gaps', [str(g) for g in mining.DEFAULT_GAPS],
                  'Pair each scan with the ones this many scans later.')
flags.DEFINE_string('poses', None, 'Ground-truth poses of the scans (KITTI layout), to '
                    'report the kept labels\' precision; never read while mining.')
flags.DEFINE_enum('format', 'auto', ['auto', *io.BIN_FORMATS], '.bin layout.')
flags.DEFINE_integer('workers', mining.DEFAULT_WORKERS, 'Processes registering pairs at once '
                     '(the pairs found do not depend on it).')
flags.mark_flags_as_required(['scans', 'out'])


def report(pairs: list[mined_pairs.MinedPair], scans: list[str],
           poses_path: str | None) -> str:
  """The lines printed after mining: pairs kept by gap, and their precision vs `--poses`."""
  lines = []
  for g in sorted({p.gap for p in pairs}):
    at = [p for p in pairs if p.gap == g]
    lines.append(f'gap {g}: {sum(p.kept for p in at)} of {len(at)} pairs kept '
                 f'({sum(p.confident for p in at)} confident)')
  kept = [p for p in pairs if p.kept]
  if poses_path and kept:
    poses = kitti.read_poses(poses_path)
    if len(poses) != len(scans):
      raise errors.UserError(f'--poses {poses_path}: {len(poses)} poses for {len(scans)} scans')
    e = mining.label_errors(kept, poses, {s: n for n, s in enumerate(scans)})
    lines.append(f'kept labels vs --poses: {np.mean(e["success"]):.1%} within 2 m / 5 deg '
                 f'({int(np.sum(~e["success"]))} wrong of {len(kept)}); median error '
                 f'{np.median(e["rte"]):.3f} m, {np.median(e["rre"]):.2f} deg')
  return '\n'.join(lines)


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f'Unexpected arguments: {argv[1:]}')
  quiet_libraries()
  try:
    gaps = [int(g) for g in FLAGS.gaps]
  except ValueError:
    raise errors.UserError(f'--gaps: whole numbers, got {",".join(FLAGS.gaps)}') from None
  cli.check_writable(FLAGS.out)
  try:
    scans = [str(p) for p in io.list_clouds(FLAGS.scans)]
  except io.CloudFileError as e:
    raise errors.UserError(f'--scans: {e}') from None
  if len(scans) < 3:
    raise errors.UserError(f'--scans {FLAGS.scans}: {len(scans)} scan(s); mining needs 3 or '
                           'more in capture order')
  with tqdm.tqdm(total=len(mining.candidate_pairs(len(scans), gaps)), desc='mining',
                 unit='pair') as bar:
    pairs = mining.mine_to_file(FLAGS.out, scans,
                                functools.partial(clean.read_metres, fmt=FLAGS.format),
                                gaps=gaps, progress=bar.update, say=bar.write,
                                workers=FLAGS.workers)
    bar.total = bar.n   # the total counted every gap; mining stops at the first that fails
    bar.refresh()
  print(f'wrote {FLAGS.out}: {sum(p.kept for p in pairs)} of {len(pairs)} candidate pairs '
        f'kept from {len(scans)} scans')
  print(report(pairs, scans, FLAGS.poses))


def console():
  """The `ssd-jax-mine` command (pyproject.toml)."""
  cli.run(main)


if __name__ == '__main__':
  console()
