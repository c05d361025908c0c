"""Registration test sets: pairs of cloud files with their ground-truth T_12.

Layouts (docs/method.md §4, §9), all with 3DFeat-Net's `groundtruths.txt`:
  * Oxford: ROOT/groundtruths.txt and ROOT/test_models/<idx>.bin;
  * processed KITTI: ROOT/<seq>/groundtruths.txt and ROOT/<seq>/%06d.bin, or a
    single such sequence folder ROOT/groundtruths.txt + ROOT/%06d.bin.
The synthetic `test_oxford/` and `test_kitti/` folders use the same layouts.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np

from ssd_jax.data import groundtruth
from ssd_jax.data.io import CloudFileError


@dataclasses.dataclass(frozen=True)
class RegistrationPair:
  sequence: str
  idx1: int
  idx2: int
  cloud1: Path
  cloud2: Path
  transform: np.ndarray   # [4, 4] T_12


def _cloud_path(folder: Path, idx: int) -> Path:
  for name in (f'{idx:06d}.bin', f'{idx}.bin'):
    if (folder / name).is_file():
      return folder / name
  raise CloudFileError(f'{folder}: no cloud file for index {idx} ({idx:06d}.bin or {idx}.bin)')


def _pairs_in(folder: Path, gt_file: Path, sequence: str) -> list[RegistrationPair]:
  return [RegistrationPair(sequence, p.idx1, p.idx2, _cloud_path(folder, p.idx1),
                           _cloud_path(folder, p.idx2), p.transform)
          for p in groundtruth.read_groundtruths(gt_file)]


def read_registration_set(root: str | os.PathLike) -> list[RegistrationPair]:
  """Every pair of an Oxford-, KITTI- or sequence-folder-layout test set."""
  root = Path(root)
  if not root.is_dir():
    raise CloudFileError(f'{root}: no such test-set directory')
  if (root / 'groundtruths.txt').is_file():
    folder = root / 'test_models' if (root / 'test_models').is_dir() else root
    return _pairs_in(folder, root / 'groundtruths.txt', root.name)
  pairs = []
  for seq in sorted(p for p in root.iterdir() if (p / 'groundtruths.txt').is_file()):
    pairs += _pairs_in(seq, seq / 'groundtruths.txt', seq.name)
  if not pairs:
    raise CloudFileError(f'{root}: no groundtruths.txt here or in its sub-folders; expected an '
                         'Oxford (test_models/ + groundtruths.txt) or KITTI (<seq>/groundtruths.txt)'
                         ' test set')
  return pairs


# A cross-sensor set's pairs.tsv: which sensor saw each cloud and how far apart they stood.
PAIR_INFO = 'pairs.tsv'
PAIR_INFO_COLUMNS = ('idx1', 'idx2', 'sensor1', 'sensor2', 'distance_m', 'yaw_deg', 'source')
# A real drive's pairs (`real_drives`) add the share of cloud 2 within 0.5 m of cloud 1 under
# the true pose.
OVERLAP_COLUMN = 'overlap'


def write_pair_info(folder: str | os.PathLike, rows: list[dict]) -> None:
  """FOLDER/pairs.tsv with `PAIR_INFO_COLUMNS`, and OVERLAP_COLUMN where the rows have
  it (floats to 3 decimals)."""
  fmt = lambda v: f'{v:.3f}' if isinstance(v, float) else str(v)
  columns = PAIR_INFO_COLUMNS + ((OVERLAP_COLUMN,) if rows and OVERLAP_COLUMN in rows[0] else ())
  lines = ['\t'.join(columns)] + ['\t'.join(fmt(r[c]) for c in columns) for r in rows]
  (Path(folder) / PAIR_INFO).write_text('\n'.join(lines) + '\n')


def read_pair_info(folder: str | os.PathLike) -> dict[tuple[int, int], dict]:
  """(idx1, idx2) -> {sensor1, sensor2, distance_m, yaw_deg, source[, overlap]} of
  FOLDER/pairs.tsv, or a CloudFileError naming what is wrong with it."""
  path = Path(folder) / PAIR_INFO
  if not path.is_file():
    raise CloudFileError(f'{path}: missing (a cross-sensor set names each pair\'s sensors '
                         'and distance there)')
  lines = path.read_text().splitlines()
  columns = tuple(lines[0].split('\t')) if lines else ()
  if columns not in (PAIR_INFO_COLUMNS, PAIR_INFO_COLUMNS + (OVERLAP_COLUMN,)):
    raise CloudFileError(f'{path}: the header must be {" ".join(PAIR_INFO_COLUMNS)} '
                         f'[{OVERLAP_COLUMN}]')
  info = {}
  for n, line in enumerate(lines[1:], 2):
    parts = line.split('\t')
    try:
      row = dict(zip(columns, parts, strict=True))
      for key in ('distance_m', 'yaw_deg', OVERLAP_COLUMN):
        if key in row:
          row[key] = float(row[key])
      info[int(row['idx1']), int(row['idx2'])] = row
    except ValueError:
      raise CloudFileError(f'{path}, line {n}: expected {len(columns)} tab-separated '
                           f'fields with numeric indices and distance, got {line!r}') from None
  return info
