"""Markdown and CSV tables of the evaluation reports."""

from __future__ import annotations

import csv
import os
from typing import Sequence


def markdown_table(header: Sequence[str], rows: Sequence[Sequence]) -> str:
  lines = ['| ' + ' | '.join(str(h) for h in header) + ' |', '|' + '---|' * len(header)]
  lines += ['| ' + ' | '.join(str(c) for c in row) + ' |' for row in rows]
  return '\n'.join(lines) + '\n'


def write_csv(path: str | os.PathLike, header: Sequence[str], rows: Sequence[Sequence]) -> None:
  with open(path, 'w', newline='') as f:
    csv.writer(f).writerows([list(header)] + [list(r) for r in rows])


def fmt(value: float, digits: int = 2) -> str:
  """A number, or '-' for NaN/None (an empty subset)."""
  if value is None or value != value:
    return '-'
  return f'{value:.{digits}f}'
