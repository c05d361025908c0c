"""Point-cloud file readers (host side, numpy) with clear errors for bad files.

Supported:
  * `.bin` float32 rows: 3DFeat-Net `xyzn` (N x 6: x y z nx ny nz), KITTI
    velodyne `xyzi` (N x 4: x y z reflectance) or plain `xyz` (N x 3);
  * `.npy` arrays [N, >=3];
  * `.ply` and `.pcd` through Open3D;
  * the 3DFeat-Net Oxford training index `train.txt`
    (`file.bin | positive indices | non-negative indices`, 0-based).
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np

BIN_FORMATS = {'xyz': 3, 'xyzi': 4, 'xyzn': 6}
CLOUD_SUFFIXES = ('.bin', '.npy', '.ply', '.pcd')


class CloudFileError(ValueError):
  """A point-cloud file is missing, empty, truncated or not in the expected format."""


def _looks_like_normals(rows: np.ndarray) -> bool:
  """Columns 3:6 of a candidate N x 6 file look like normals: never longer than 1 and
  mostly unit length. (Real processed KITTI has ~20 % shorter, unnormalised ones.)"""
  norms = np.linalg.norm(rows[:, 3:6], axis=1)
  finite = np.isfinite(norms)
  if not finite.any():
    return False
  norms = norms[finite]
  return bool(np.mean(norms <= 1.01) > 0.99 and np.median(norms) > 0.9)


def _looks_like_intensity(rows: np.ndarray) -> bool:
  """Column 3 of a candidate N x 4 file is a reflectance in [0, 1] (KITTI) or [0, 255]."""
  col = rows[:, 3]
  col = col[np.isfinite(col)]
  return col.size > 0 and (bool(np.all((col >= 0) & (col <= 1))) or
                           bool(np.all((col >= 0) & (col <= 255) & (col == np.round(col)))))


def detect_bin_format(raw: np.ndarray, path: str | os.PathLike) -> str:
  """Guess the row layout of a float32 `.bin` from its size and contents."""
  candidates = [f for f, w in BIN_FORMATS.items() if raw.size % w == 0]
  if not candidates:
    raise CloudFileError(
        f'{path}: {raw.size * 4} bytes is not a whole number of float32 rows of width 3, 4 '
        f'or 6 (truncated file?)')
  sample = slice(0, min(raw.size, 6 * 4096))
  if 'xyzn' in candidates and _looks_like_normals(raw[sample].reshape(-1, 6)):
    return 'xyzn'
  if 'xyzi' in candidates and _looks_like_intensity(raw[: min(raw.size, 4 * 4096)].reshape(-1, 4)):
    return 'xyzi'
  if 'xyz' in candidates:
    return 'xyz'
  raise CloudFileError(
      f'{path}: cannot tell the row layout ({raw.size * 4} bytes); pass the format '
      f"explicitly (one of {sorted(BIN_FORMATS)})")


def read_bin(path: str | os.PathLike, fmt: str = 'auto') -> np.ndarray:
  """Read a float32 `.bin` cloud -> xyz [N, 3] float32 metres."""
  if fmt != 'auto' and fmt not in BIN_FORMATS:
    raise CloudFileError(f"unknown .bin format {fmt!r}; use 'auto' or one of {sorted(BIN_FORMATS)}")
  size = os.path.getsize(path)
  if size == 0:
    raise CloudFileError(f'{path}: file is empty')
  if size % 4:
    raise CloudFileError(f'{path}: {size} bytes is not a whole number of float32 values '
                         '(truncated file?)')
  raw = np.fromfile(path, dtype='<f4')
  fmt = detect_bin_format(raw, path) if fmt == 'auto' else fmt
  width = BIN_FORMATS[fmt]
  if raw.size % width:
    raise CloudFileError(f'{path}: {size} bytes is not a whole number of {width}-column '
                         f"float32 rows (format {fmt!r}); truncated file or wrong format?")
  return np.ascontiguousarray(raw.reshape(-1, width)[:, :3])


def read_cloud(path: str | os.PathLike, fmt: str = 'auto') -> np.ndarray:
  """Read any supported cloud file -> xyz [N, 3] float32 metres (may hold NaN rows)."""
  path = Path(path)
  if not path.is_file():
    raise CloudFileError(f'{path}: no such file')
  suffix = path.suffix.lower()
  if suffix == '.bin':
    return read_bin(path, fmt)
  if suffix == '.npy':
    try:
      arr = np.load(path)
    except ValueError as e:
      raise CloudFileError(f'{path}: not a readable .npy array ({e})') from None
    if arr.ndim != 2 or arr.shape[1] < 3:
      raise CloudFileError(f'{path}: expected an [N, >=3] array, got shape {arr.shape}')
    return np.ascontiguousarray(arr[:, :3], dtype=np.float32)
  if suffix in ('.ply', '.pcd'):
    import open3d as o3d  # pylint: disable=g-import-not-at-top
    if path.stat().st_size == 0:
      raise CloudFileError(f'{path}: file is empty')
    pcd = o3d.io.read_point_cloud(str(path))
    pts = np.asarray(pcd.points, dtype=np.float32)
    if pts.size == 0:
      raise CloudFileError(f'{path}: Open3D read no points (empty or unreadable {suffix} file)')
    return pts
  raise CloudFileError(f'{path}: unsupported file type {suffix!r}; supported: {CLOUD_SUFFIXES}')


@dataclasses.dataclass(frozen=True)
class IndexEntry:
  """One line of a 3DFeat-Net `train.txt`."""
  path: Path
  positives: tuple[int, ...]
  non_negatives: tuple[int, ...]


def _parse_indices(field: str) -> tuple[int, ...]:
  return tuple(int(tok) for tok in field.replace(',', ' ').split())


def read_oxford_index(path: str | os.PathLike) -> list[IndexEntry]:
  """Parse `train.txt`: `file.bin | 1 2 3 | 4 5` per line, paths relative to the file."""
  path = Path(path)
  if not path.is_file():
    raise CloudFileError(f'{path}: no such index file')
  entries = []
  for lineno, line in enumerate(path.read_text().splitlines(), 1):
    if not line.strip():
      continue
    fields = [f.strip() for f in line.split('|')]
    if len(fields) != 3:
      raise CloudFileError(f'{path}:{lineno}: expected "file | positives | non-negatives", '
                           f'got {line!r}')
    try:
      entries.append(IndexEntry(path.parent / fields[0], _parse_indices(fields[1]),
                                _parse_indices(fields[2])))
    except ValueError:
      raise CloudFileError(f'{path}:{lineno}: indices must be integers, got {line!r}') from None
  if not entries:
    raise CloudFileError(f'{path}: index lists no clouds')
  return entries


def list_clouds(source: str | os.PathLike) -> list[Path]:
  """Cloud files of a source: a directory (its `train.txt` if it has one, else every
  supported file in it, sorted), an index `.txt`, or a single cloud file."""
  source = Path(source)
  if source.is_dir():
    if (source / 'train.txt').is_file():
      return [e.path for e in read_oxford_index(source / 'train.txt')]
    files = sorted(p for p in source.iterdir() if p.suffix.lower() in CLOUD_SUFFIXES)
    if not files:
      raise CloudFileError(f'{source}: directory holds no point clouds ({CLOUD_SUFFIXES})')
    return files
  if source.suffix == '.txt':
    return [e.path for e in read_oxford_index(source)]
  if source.is_file():
    return [source]
  raise CloudFileError(f'{source}: no such file or directory')


def write_bin(path: str | os.PathLike, points: np.ndarray,
              normals: np.ndarray | None = None) -> None:
  """Write float32 rows: `xyzn` (3DFeat-Net N x 6) with normals, else `xyz` (N x 3)."""
  cols = [np.asarray(points, np.float32)]
  if normals is not None:
    cols.append(np.asarray(normals, np.float32))
  np.ascontiguousarray(np.concatenate(cols, axis=1), dtype='<f4').tofile(path)
