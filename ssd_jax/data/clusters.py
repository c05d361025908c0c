"""The descriptor-matching set (docs/method.md §4): pairs of 4 m clusters, label 1/0.

Layout:

    clusters/filenames.txt   a header line, then one line per pair ending in its
                             label (1 = the same place, 0 = clouds >= 20 m apart)
    clusters/<i>_0.bin       the pair's first cluster, keypoint at the origin
    clusters/<i>_1.bin       its second cluster

A line names its pair index first. Where a line also names the two files (this
project's synthetic sets write `i  i_0.bin  i_1.bin  label`), those are used;
otherwise the files are `<i>_0.bin` and `<i>_1.bin`. Fields are separated by
tabs, spaces or commas.
"""

from __future__ import annotations

import dataclasses
import os
import re
from pathlib import Path

from ssd_jax.data.io import CloudFileError


@dataclasses.dataclass(frozen=True)
class ClusterPair:
  index: int
  cluster0: Path
  cluster1: Path
  label: int        # 1: the same place seen twice; 0: clouds at least 20 m apart


def _fields(line: str) -> list[str]:
  return [f for f in re.split(r'[\s,]+', line.strip()) if f]


def read_cluster_pairs(folder: str | os.PathLike, check_files: bool = True) -> list[ClusterPair]:
  """Every pair listed in folder/filenames.txt, in file order."""
  folder = Path(folder)
  index_file = folder / 'filenames.txt'
  if not index_file.is_file():
    raise CloudFileError(f'{folder}: no filenames.txt; expected a descriptor-matching folder '
                         '(filenames.txt + <i>_0.bin / <i>_1.bin)')
  lines = index_file.read_text().splitlines()
  pairs = []
  for n, line in enumerate(lines, 1):
    fields = _fields(line)
    if not fields:
      continue
    if n == 1 and fields[-1] not in ('0', '1'):
      continue   # the header
    where = f'{index_file}:{n}'
    if fields[-1] not in ('0', '1') or len(fields) < 2:
      raise CloudFileError(f'{where}: expected "<pair index> [<file 0> <file 1>] <label 0/1>", '
                           f'got {line.strip()!r}')
    try:
      index = int(fields[0])
    except ValueError:
      raise CloudFileError(f'{where}: pair index {fields[0]!r} is not an integer') from None
    names = [f for f in fields[1:-1] if f.lower().endswith('.bin')]
    if len(names) != 2:
      names = [f'{index}_0.bin', f'{index}_1.bin']
    pair = ClusterPair(index, folder / names[0], folder / names[1], int(fields[-1]))
    if check_files:
      for path in (pair.cluster0, pair.cluster1):
        if not path.is_file():
          raise CloudFileError(f'{where}: cluster file {path} is missing')
    pairs.append(pair)
  if not pairs:
    raise CloudFileError(f'{index_file}: lists no cluster pairs')
  return pairs
