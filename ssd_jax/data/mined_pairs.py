"""The miner's file: every candidate pair of scans it registered (`registration.mining`), with
its transform, whether the gate kept it and why not. Training reads the kept pairs
(`datasets.MinedPairDataset`); nothing here holds or reads a ground-truth pose.

CSV columns (`HEADER`): cloud1, cloud2 (paths), gap (scans apart in capture order),
fitness (verified share of cloud 2's structure laid on cloud 1), confident, kept (0/1),
reason (why not kept), then T_12 row-major (maps cloud 2 into cloud 1's frame, metres).
"""

from __future__ import annotations

import csv
import dataclasses
import os
from typing import Iterable, Sequence

import numpy as np

from ssd_jax.infra import errors

HEADER = ['cloud1', 'cloud2', 'gap', 'fitness', 'confident', 'kept', 'reason',
          *[f'T_12[{i}][{j}]' for i in range(4) for j in range(4)]]


@dataclasses.dataclass
class MinedPair:
  """One candidate pair: T_12 [4, 4] maps cloud 2 into cloud 1's frame."""
  cloud1: str
  cloud2: str
  gap: int                 # scans apart in capture order
  transform: np.ndarray    # [4, 4]
  fitness: float           # verified share of cloud 2's structure laid on cloud 1
  confident: bool
  kept: bool = False
  reason: str = ''         # why it is not kept ('' if it is), one line

  def row(self) -> list:
    return [self.cloud1, self.cloud2, self.gap, f'{self.fitness:.4f}', int(self.confident),
            int(self.kept), self.reason, *[f'{v:.10g}' for v in self.transform.ravel()]]

  @classmethod
  def from_row(cls, row: Sequence[str]) -> 'MinedPair':
    return cls(row[0], row[1], int(row[2]), np.array(row[7:23], np.float64).reshape(4, 4),
               float(row[3]), bool(int(row[4])), bool(int(row[5])), row[6])


class PairsFile:
  """The miner's CSV at `path` (`HEADER`): registered pairs are appended as they come
  (`add`), so a stopped run keeps them (`done` on the next), and `write` replaces the file
  with every pair after the gate."""

  def __init__(self, path: str):
    self.path = path
    self.done: dict[tuple[str, str], MinedPair] = {}
    if os.path.exists(path):
      with open(path, newline='') as f:
        rows = list(csv.reader(f))
      if rows and rows[0] != HEADER:
        raise errors.UserError(f'{path}: not a file of mined pairs (its columns differ); '
                               'give another --out or remove it')
      for r in rows[1:]:
        if len(r) == len(HEADER):
          p = MinedPair.from_row(r)
          self.done[p.cloud1, p.cloud2] = p
    else:
      with open(path, 'w', newline='') as f:
        csv.writer(f).writerow(HEADER)

  def add(self, pair: MinedPair) -> None:
    with open(self.path, 'a', newline='') as f:
      csv.writer(f).writerow(pair.row())

  def write(self, pairs: Iterable[MinedPair]) -> None:
    with open(self.path + '.tmp', 'w', newline='') as f:
      csv.writer(f).writerows([HEADER, *(p.row() for p in pairs)])
    os.replace(self.path + '.tmp', self.path)


def read_kept(path: str) -> list[MinedPair]:
  """The kept pairs of a miner's CSV (what training reads)."""
  try:
    with open(path, newline='') as f:
      rows = list(csv.reader(f))
  except FileNotFoundError:
    raise errors.UserError(f'{path}: no such file of mined pairs (experiments.mine writes '
                           'it)') from None
  except OSError as e:
    raise errors.UserError(f'{path}: {e.strerror}') from None
  if not rows or rows[0] != HEADER:
    raise errors.UserError(f'{path}: not a file of mined pairs (experiments.mine writes them)')
  pairs = [MinedPair.from_row(r) for r in rows[1:] if len(r) == len(HEADER)]
  kept = [p for p in pairs if p.kept]
  if not kept:
    raise errors.UserError(f'{path}: none of its {len(pairs)} pairs passed the gate')
  return kept


def chained(pairs: Sequence[MinedPair], max_links: int) -> list[MinedPair]:
  """The kept `pairs` and the farther pairs composed of up to `max_links` of them in
  capture order (scan 1 before scan 2, as the miner writes them): T_ik = T_ij T_jk, its
  gap the links' sum, its fitness their least. Each composed pair comes from its
  shortest chain, and a pair the miner kept is never replaced. The miner stops where its
  teacher no longer registers (`mining.MIN_YIELD`), so chains reach past it; each link's
  error adds up (the VLP-16 drive's: median 0.04 m / 0.4 deg a link)."""
  if max_links < 1:
    raise ValueError(f'max_links must be 1 or more, got {max_links}')
  out = {(p.cloud1, p.cloud2): p for p in pairs}
  onward: dict[str, list[MinedPair]] = {}
  for p in pairs:
    onward.setdefault(p.cloud1, []).append(p)
  frontier = list(pairs)
  for _ in range(2, max_links + 1):
    grown = []
    for p in frontier:
      for q in onward.get(p.cloud2, ()):
        if (p.cloud1, q.cloud2) in out:
          continue
        pair = MinedPair(p.cloud1, q.cloud2, p.gap + q.gap, p.transform @ q.transform,
                         min(p.fitness, q.fitness), True, True, reason='')
        out[p.cloud1, q.cloud2] = pair
        grown.append(pair)
    frontier = grown
  return list(out.values())
