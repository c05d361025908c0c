"""Point-cloud file readers (host side, numpy) with clear errors for bad files.

Supported:
  * `.bin` rows of float32: 3DFeat-Net `xyzn` (N x 6: x y z nx ny nz), KITTI
    velodyne `xyzi` (N x 4: x y z reflectance) or plain `xyz` (N x 3), or the same
    layouts in float64 (`xyzn64`, `xyzi64`, `xyz64`); detected from the bytes
    (`detect_bin_format`, which refuses rather than guesses) or named;
  * `.npy` arrays [N, >=3];
  * `.ply` and `.pcd` through Open3D; `.las` / `.laz` through laspy;
  * text, one point a line (`.xyz`, `.pts`, `.txt`, `.csv`: `read_text`), and legacy
    VTK point sets (`.vtk`, ASCII or binary: `read_vtk`);
  * the 3DFeat-Net Oxford training index `train.txt`
    (`file.bin | positive indices | non-negative indices`, 0-based).
"""

from __future__ import annotations

import dataclasses
import io as text_io
import os
from pathlib import Path
import re

import numpy as np

from ssd_jax.infra import errors


# .bin row layouts: name -> (little-endian dtype, columns). The first three columns are
# x y z in metres; `i` is an intensity / reflectance, `n` a unit normal.
BIN_FORMATS = {
    'xyz': ('<f4', 3), 'xyzi': ('<f4', 4), 'xyzn': ('<f4', 6),
    'xyz64': ('<f8', 3), 'xyzi64': ('<f8', 4), 'xyzn64': ('<f8', 6),
}
# Auto-detection prefers the layout whose extra columns carry evidence (normals, then
# an intensity) over plain xyz, which any byte count divisible by 12 also fits.
_PREFERENCE = ('xyzn', 'xyzn64', 'xyzi', 'xyzi64', 'xyz', 'xyz64')
# What a folder of scans is listed by (`list_clouds`); `.txt` and `.csv` files are read
# when named (a folder's .txt is more often an index or poses).
CLOUD_SUFFIXES = ('.bin', '.npy', '.ply', '.pcd', '.las', '.laz', '.xyz', '.pts', '.vtk')
TEXT_SUFFIXES = ('.xyz', '.pts', '.txt', '.csv')
# Metres. Beyond it a value is read garbage, not a coordinate (UTM northings are ~1e7).
MAX_COORDINATE = 1e8
_DETECT_ROWS = 8192


class CloudFileError(errors.UserError):
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


def _coordinate_problem(xyz: np.ndarray, max_nonfinite: float = 0.01) -> str | None:
  """Why columns 0:3 [N, 3] (float64) cannot be metres, or None. Bytes of another
  type or width read as floats give non-finite, astronomically large or denormal-small
  values; a cloud may hold up to `max_nonfinite` of NaN rows (missing returns)."""
  finite = np.isfinite(xyz).all(axis=1)
  if 1 - finite.mean() > max_nonfinite:
    return f'{100 * (1 - finite.mean()):.0f} % of the rows are not finite'
  mag = np.abs(xyz[finite])
  if mag.size and mag.max() > MAX_COORDINATE:
    return f'coordinates up to {mag.max():.1e} m'
  # Garbage reads spread over float exponents (1e-38 ... 1e38); a coordinate, or the
  # float32 residue of subtracting two of them, is never below a picometre.
  if np.mean((mag > 0) & (mag < 1e-12)) > 0.01:
    return 'coordinates below a picometre'
  return None


def _layout_problem(rows: np.ndarray, fmt: str) -> str | None:
  """Why the sampled rows [M, columns] (float64) of layout `fmt` are implausible, or
  None when they look like a point cloud in that layout."""
  problem = _coordinate_problem(rows[:, :3])
  if problem:
    return problem
  rows = rows[np.isfinite(rows[:, :3]).all(axis=1)]
  xyz = rows[:, :3]
  width = rows.shape[1]
  if width == 3 and np.mean(np.abs(np.linalg.norm(xyz, axis=1) - 1) < 0.01) > 0.2:
    return 'a fifth of the rows are unit vectors (normals of an N x 6 file?)'
  if width == 6 and not _looks_like_normals(rows):
    return 'columns 4-6 are not unit normals'
  if width == 4:
    value = rows[:, 3]
    if not np.isfinite(value).all() or value.min() < 0 or value.max() > 65535:
      return (f'column 4 spans [{np.nanmin(value):.3g}, {np.nanmax(value):.3g}], not an '
              'intensity')
    # An N x 3 file read 4 columns wide puts coordinates in column 4: it is then
    # distributed like the coordinates, which an intensity never is.
    if ks_statistic(value, xyz.ravel()) < 0.1:
      return 'column 4 is distributed like the coordinates, not like an intensity'
  return None


def ks_statistic(a: np.ndarray, b: np.ndarray) -> float:
  """The two-sample Kolmogorov-Smirnov statistic: the largest gap between the empirical
  CDFs of samples a [n] and b [m] (scipy.stats.ks_2samp's, without importing
  scipy.stats, a second of every command's start)."""
  a, b = np.sort(np.ravel(a)), np.sort(np.ravel(b))
  grid = np.concatenate([a, b])
  return float(np.max(np.abs(np.searchsorted(a, grid, side='right') / len(a)
                             - np.searchsorted(b, grid, side='right') / len(b))))


def _sample_rows(data: np.ndarray, fmt: str) -> np.ndarray | None:
  """Up to _DETECT_ROWS rows spread over the file, as float64, or None when the byte
  count is not a whole number of `fmt` rows."""
  dtype, width = BIN_FORMATS[fmt]
  row_bytes = np.dtype(dtype).itemsize * width
  if data.size % row_bytes:
    return None
  rows = data.view(dtype).reshape(-1, width)
  # Evenly spread; with a step of one row or more their floors never repeat.
  pick = (np.arange(len(rows)) if len(rows) <= _DETECT_ROWS else
          np.linspace(0, len(rows) - 1, _DETECT_ROWS).astype(int))
  with np.errstate(all='ignore'):
    return rows[pick].astype(np.float64)


def detect_bin_format(data: np.ndarray, path: str | os.PathLike) -> str:
  """The row layout of a `.bin` file's bytes (any array, read as raw bytes): the one
  layout of BIN_FORMATS whose sampled rows are plausible, preferring layouts whose
  extra columns look like normals or an intensity. Raises CloudFileError naming every
  layout tried and why it was refused, or the layouts it cannot tell apart."""
  data = np.ascontiguousarray(data).reshape(-1).view(np.uint8)
  plausible, refused = [], []
  for fmt in _PREFERENCE:
    rows = _sample_rows(data, fmt)
    problem = ('not a whole number of rows' if rows is None else
               'no rows' if not len(rows) else _layout_problem(rows, fmt))
    if problem:
      refused.append(f'{fmt}: {problem}')
    else:
      plausible.append(fmt)
  if not plausible:
    raise CloudFileError(f'{path}: {data.size} bytes fit no .bin layout ({"; ".join(refused)}); '
                         f'truncated or not a point cloud? --format names one of '
                         f'{sorted(BIN_FORMATS)}')
  dtypes = {BIN_FORMATS[f][0] for f in plausible}
  if len(dtypes) > 1:
    raise CloudFileError(f'{path}: cannot tell float32 from float64 rows (both {plausible} '
                         'look plausible); pass the layout with --format')
  return plausible[0]


def read_bin(path: str | os.PathLike, fmt: str = 'auto') -> np.ndarray:
  """Read a `.bin` cloud -> xyz [N, 3] metres: float32 for the float32 layouts, float64
  for the `*64` ones (so that far-from-origin coordinates keep their precision).

  fmt: 'auto' (detect_bin_format) or a key of BIN_FORMATS. A named layout is still
  checked for values no point cloud holds (bytes of another type)."""
  return read_bin_rows(path, fmt)[:, :3].copy()


def read_bin_rows(path: str | os.PathLike, fmt: str = 'auto') -> np.ndarray:
  """`read_bin` with every column of the layout: [N, 3 | 4 | 6] (xyz, then an intensity
  or a unit normal)."""
  if fmt != 'auto' and fmt not in BIN_FORMATS:
    raise CloudFileError(f"unknown .bin format {fmt!r}; use 'auto' or one of {sorted(BIN_FORMATS)}")
  size = os.path.getsize(path)
  if size == 0:
    raise CloudFileError(f'{path}: file is empty')
  if size % 4:
    raise CloudFileError(f'{path}: {size} bytes is not a whole number of float32 values '
                         '(truncated file?)')
  data = np.fromfile(path, dtype=np.uint8)
  if fmt == 'auto':
    fmt = detect_bin_format(data, path)
  else:
    rows = _sample_rows(data, fmt)
    dtype, width = BIN_FORMATS[fmt]
    if rows is None:
      raise CloudFileError(f'{path}: {size} bytes is not a whole number of {width}-column '
                           f'{np.dtype(dtype).name} rows (format {fmt!r}); truncated file or '
                           'wrong format?')
    # Named: NaN rows are the file's own (clean_cloud drops them); only values no
    # cloud holds say the layout is wrong.
    problem = _coordinate_problem(rows[:, :3], max_nonfinite=1.0)
    if problem:
      raise CloudFileError(f'{path}: read as {fmt!r} it holds {problem}: wrong --format?')
  dtype, width = BIN_FORMATS[fmt]
  return np.ascontiguousarray(data.view(dtype).reshape(-1, width)).astype(
      np.dtype(dtype).newbyteorder('='))


# Bytes a point costs at the peak of reading, cleaning, centring and putting a cloud on
# the grid (float32 rows, float64 copies, Open3D's own copy; measured ~100 on a 2 M-point
# scan), with a margin.
BYTES_PER_POINT = 160


def available_memory() -> int:
  """Bytes the system can still give this process (MemAvailable; the physical memory
  where /proc/meminfo is absent)."""
  try:
    with open('/proc/meminfo') as f:
      for line in f:
        if line.startswith('MemAvailable:'):
          return int(line.split()[1]) * 1024
  except OSError:
    pass
  return os.sysconf('SC_PAGE_SIZE') * os.sysconf('SC_PHYS_PAGES')


def estimated_points(path: Path) -> int:
  """A cheap upper-end estimate of the points in a cloud file, from its size or header."""
  suffix, size = path.suffix.lower(), path.stat().st_size
  if suffix == '.npy':
    try:
      return int(np.load(path, mmap_mode='r').shape[0])
    except (ValueError, IndexError, OSError):
      return size // 12
  if suffix == '.laz':
    import laspy  # pylint: disable=g-import-not-at-top  (only for LAS input)
    try:
      with laspy.open(path) as f:
        return int(f.header.point_count)
    except Exception:  # pylint: disable=broad-except  (the reader names a bad file)
      return 0
  # .bin: KITTI's 16-byte xyzi rows, the common case (xyz rows: 25 % more points than this,
  # within BYTES_PER_POINT's margin); .las: its smallest point record; text: three short
  # numbers; .ply/.pcd/.vtk: xyz float32.
  return size // {'.bin': 16, '.las': 20, **dict.fromkeys(TEXT_SUFFIXES, 24)}.get(suffix, 12)


def check_memory(path: Path) -> None:
  """Refuse, in one line, a cloud file whose points would not fit in the memory this
  process can still get (`BYTES_PER_POINT` each), before reading it."""
  n = estimated_points(path)
  need, have = n * BYTES_PER_POINT, available_memory()
  if need > have:
    raise CloudFileError(
        f'{path}: ~{n:,} points need ~{need / 2**30:.1f} GiB to read and put on a grid, '
        f'{have / 2**30:.1f} GiB is available; split it into tiles or voxelise it first '
        '(e.g. Open3D voxel_down_sample)')


def read_cloud(path: str | os.PathLike, fmt: str = 'auto') -> np.ndarray:
  """Read any supported cloud file -> xyz [N, 3] metres (may hold NaN rows): float32,
  or float64 where the file stores float64 (`*64` .bin layouts, float64 .npy, and
  .ply/.pcd, which Open3D reads as float64), so far-from-origin coordinates keep
  their precision until a caller centres them."""
  path = Path(path)
  if not path.is_file():
    raise CloudFileError(f'{path}: no such file')
  check_memory(path)
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
    wide = arr.dtype == np.float64
    return np.ascontiguousarray(arr[:, :3], dtype=np.float64 if wide else np.float32)
  if suffix in ('.ply', '.pcd'):
    import open3d as o3d  # pylint: disable=g-import-not-at-top
    if path.stat().st_size == 0:
      raise CloudFileError(f'{path}: file is empty')
    pcd = o3d.io.read_point_cloud(str(path))
    pts = np.asarray(pcd.points, dtype=np.float64)
    if pts.size == 0:
      raise CloudFileError(f'{path}: Open3D read no points (empty or unreadable {suffix} file)')
    return pts
  if suffix in ('.las', '.laz'):
    return _read_las(path)
  if suffix in TEXT_SUFFIXES:
    return read_text(path)
  if suffix == '.vtk':
    return read_vtk(path)
  raise CloudFileError(f'{path}: unsupported file type {suffix!r}; supported: '
                       f'{" ".join(sorted(set(CLOUD_SUFFIXES + TEXT_SUFFIXES)))}')


_NUMBER = re.compile(r'^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^[-+]?(nan|inf)$', re.I)


def read_text(path: str | os.PathLike) -> np.ndarray:
  """xyz [N, 3] float64 of a text cloud, one point a line, numbers split by commas,
  semicolons, spaces or tabs: the columns a header line names x, y, z (any case, e.g.
  `x,y,z,intensity`), else the first three. Lines before the first of three or more
  numbers (headers, a `.pts` point count) are skipped."""
  path = Path(path)
  try:
    lines = path.read_text().splitlines()
  except UnicodeDecodeError:
    raise CloudFileError(f'{path}: not a text file') from None
  split = lambda line: [f for f in re.split(r'[,;\s]+', line.strip()) if f]
  start = next((k for k, line in enumerate(lines)
                if len(split(line)) >= 3 and all(_NUMBER.match(f) for f in split(line))), None)
  if start is None:
    raise CloudFileError(f'{path}: no line of three or more numbers (x y z)')
  names = [f.strip('"\'').lower() for f in split(lines[start - 1])] if start else []
  columns = tuple(names.index(a) for a in 'xyz') if set('xyz') <= set(names) else (0, 1, 2)
  delimiter = next((d for d in ',;' if d in lines[start]), None)
  try:
    pts = np.loadtxt(text_io.StringIO('\n'.join(lines[start:])), delimiter=delimiter,
                     usecols=columns, ndmin=2, dtype=np.float64)
  except ValueError as e:
    raise CloudFileError(f'{path}: not a table of numbers after line {start + 1} ({e})') from None
  return pts


def read_vtk(path: str | os.PathLike) -> np.ndarray:
  """xyz [N, 3] float64 of a legacy VTK file's POINTS (ASCII or big-endian BINARY)."""
  path = Path(path)
  data = path.read_bytes()
  found = re.search(rb'^POINTS\s+(\d+)\s+(\w+)[^\n]*\n', data, re.M)
  if not data.startswith(b'# vtk') or found is None:
    raise CloudFileError(f'{path}: not a legacy VTK file with POINTS')
  n, kind = int(found.group(1)), found.group(2).decode().lower()
  width = {'float': 4, 'double': 8}.get(kind)
  if width is None:
    raise CloudFileError(f'{path}: VTK POINTS of type {kind!r}; float or double expected')
  body = data[found.end():]
  if re.search(rb'^BINARY\s*$', data[:found.start()], re.M):
    if len(body) < 3 * n * width:
      raise CloudFileError(f'{path}: truncated: {n} points need {3 * n * width} bytes, '
                           f'{len(body)} follow POINTS')
    return np.frombuffer(body, f'>f{width}', 3 * n).astype(np.float64).reshape(n, 3)
  values = body.split(maxsplit=3 * n)[:3 * n]
  try:
    pts = np.array(values, dtype=np.float64)
  except ValueError:
    raise CloudFileError(f'{path}: the {n} VTK POINTS are not all numbers') from None
  if len(pts) < 3 * n:
    raise CloudFileError(f'{path}: truncated: {n} points announced, {len(pts) // 3} found')
  return pts.reshape(n, 3)


def _read_las(path: Path) -> np.ndarray:
  """xyz [N, 3] float64 of an ASPRS LAS / LAZ file (laspy; LAZ through lazrs), scaled and
  offset as the header says: map coordinates keep their precision."""
  import laspy  # pylint: disable=g-import-not-at-top  (0.1 s; only for LAS input)
  if path.stat().st_size == 0:
    raise CloudFileError(f'{path}: file is empty')
  try:
    las = laspy.read(path)
  except Exception as e:  # pylint: disable=broad-except  (laspy raises many kinds)
    raise CloudFileError(f'{path}: not a readable LAS/LAZ file ({type(e).__name__}: {e})') from None
  pts = np.stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)], 1).astype(np.float64)
  if pts.size == 0:
    raise CloudFileError(f'{path}: the LAS file holds no points')
  return pts


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
