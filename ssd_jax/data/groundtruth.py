"""`groundtruths.txt`: the pair list with the transform between the two clouds of each pair.

Format (docs/method.md §4, as 3DFeat-Net's evaluation reads it): a header line, then
one line per pair, tab-separated,

    idx1  idx2  t_1  t_2  t_3  q_1  q_2  q_3  q_4

where (q_1 .. q_4) is the rotation as a unit quaternion, scalar first (MATLAB
`rotm2quat`: w x y z), and (R(q), t) is T_12: it maps points of cloud `idx2`
into the frame of cloud `idx1`. The reader also takes space-separated files.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Iterable

import numpy as np
from scipy import spatial

from ssd_jax import geometry
from ssd_jax.data.io import CloudFileError

HEADER = ('idx1', 'idx2', 't_1', 't_2', 't_3', 'q_1', 'q_2', 'q_3', 'q_4')


@dataclasses.dataclass(frozen=True)
class GroundTruthPair:
  """One registration pair: T_12 [4, 4] float64 maps cloud idx2 into cloud idx1's frame."""
  idx1: int
  idx2: int
  transform: np.ndarray


def relative_pose(poses: np.ndarray, i: int, j: int) -> np.ndarray:
  """T_ij [4, 4] from sensor poses T_world_sensor [P, 4, 4]: maps scan j's frame into
  scan i's."""
  return geometry.invert_transform(poses[i]) @ poses[j]


def close_pairs(positions: np.ndarray, max_distance: float) -> list[tuple[int, int]]:
  """Index pairs (i < j) of positions [P, 3] less than max_distance metres apart."""
  tree = spatial.cKDTree(positions)
  return sorted((int(i), int(j)) for i, j in tree.query_pairs(max_distance - 1e-9))


def write_groundtruths(path: str | os.PathLike, pairs: Iterable[GroundTruthPair]) -> None:
  lines = ['\t'.join(HEADER)]
  for pair in pairs:
    t = np.asarray(pair.transform, np.float64)
    q = geometry.matrix_to_quaternion(t[:3, :3])
    values = [*t[:3, 3], *q]
    lines.append('\t'.join([str(int(pair.idx1)), str(int(pair.idx2))] +
                           [f'{v:.9f}' for v in values]))
  Path(path).write_text('\n'.join(lines) + '\n')


def read_groundtruths(path: str | os.PathLike) -> list[GroundTruthPair]:
  """Parse a `groundtruths.txt` (header optional) -> pairs with float64 T_12."""
  path = Path(path)
  if not path.is_file():
    raise CloudFileError(f'{path}: no such ground-truth file')
  pairs = []
  for lineno, line in enumerate(path.read_text().splitlines(), 1):
    fields = line.split()
    if not fields or (lineno == 1 and fields[0].lower() == 'idx1'):
      continue
    if len(fields) != 9:
      raise CloudFileError(f'{path}:{lineno}: expected 9 fields ({" ".join(HEADER)}), '
                           f'got {len(fields)}: {line!r}')
    try:
      idx1, idx2 = int(fields[0]), int(fields[1])
      values = np.array([float(f) for f in fields[2:]], np.float64)
    except ValueError:
      raise CloudFileError(f'{path}:{lineno}: not a number in {line!r}') from None
    q = values[3:]
    if not np.all(np.isfinite(values)) or abs(np.linalg.norm(q) - 1.0) > 1e-3:
      raise CloudFileError(f'{path}:{lineno}: quaternion {q.tolist()} is not a finite unit '
                           'quaternion')
    transform = geometry.make_transform(geometry.quaternion_to_matrix(q), values[:3])
    pairs.append(GroundTruthPair(idx1, idx2, transform))
  if not pairs:
    raise CloudFileError(f'{path}: lists no pairs')
  return pairs
