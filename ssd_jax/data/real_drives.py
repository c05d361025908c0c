"""Registration pairs from real drives: sequences of LiDAR scans with a pose per scan.

A drive is a folder DRIVE/scans/NNNNNN.bin (float32 x y z intensity, the scan's own sensor
frame, metres) and DRIVE/poses.txt (one line per scan, the row-major 3 x 4 [R | t] of
T_world_scan: p_world = R p_scan + t), or a SLAM run's Scans/*.pcd and optimized_poses.txt
(`LAYOUTS`). The pair (i, j) is registered as cloud 1 = scan i,
cloud 2 = scan j, with T_12 = inv(T_i) T_j.

`make_set` picks, per drive and per distance bin, up to `per_bin` pairs spread over the
bin, and writes each twice: as driven, and with cloud 2 turned about its sensor's z by a
yaw of 180 +- 45 degrees (a place revisited from the other heading, what a loop closure
looks like; the drives themselves seldom revisit). Each pair's overlap is measured from
the poses: the share of cloud 2's points within OVERLAP_DISTANCE of cloud 1.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
from scipy import spatial

from ssd_jax import geometry
from ssd_jax.data import clean, groundtruth, io, kitti, preprocess, registration_sets
from ssd_jax.data.io import CloudFileError

# Metres: a cloud-2 point this close to cloud 1 under the true pose counts as overlapping.
OVERLAP_DISTANCE = 0.5
# Pairs are kept where at least this share of cloud 2 overlaps cloud 1 (`overlap`): a solid-
# state unit's scans taken facing apart share nothing, and no method could register them.
MIN_OVERLAP = 0.1
# Degrees: the turned copy of each pair turns cloud 2 by 180 degrees +- this.
TURN_SPREAD_DEG = 45.0


@dataclasses.dataclass(frozen=True)
class Drive:
  name: str
  scans: list[Path]       # capture order
  poses: np.ndarray       # [S, 4, 4] T_world_scan


# A drive's layouts: (scan folder, scan suffix, pose file). The first is the project's (and
# ../shared/data/real_drives'); the second SC-A-LOAM's and Fast-LIO2_SC-SLAM's output folders.
LAYOUTS = (('scans', '.bin', 'poses.txt'), ('Scans', '.pcd', 'optimized_poses.txt'))


def read_drive(folder: str | os.PathLike) -> Drive:
  """A drive folder in one of `LAYOUTS` (scans/*.bin + poses.txt, or a SLAM run's
  Scans/*.pcd + optimized_poses.txt), checked to hold one pose per scan."""
  folder = Path(folder)
  for scan_dir, suffix, pose_file in LAYOUTS:
    scans = sorted((folder / scan_dir).glob(f'*{suffix}'))
    if scans:
      poses = kitti.read_poses(folder / pose_file)
      if len(poses) != len(scans):
        raise CloudFileError(f'{folder}: {len(scans)} scans but {len(poses)} poses in '
                             f'{pose_file}')
      return Drive(folder.name, scans, poses)
  raise CloudFileError(f'{folder}: no scans (a drive is scans/NNNNNN.bin + poses.txt, or '
                       'Scans/NNNNNN.pcd + optimized_poses.txt)')


def choose_pairs(poses: np.ndarray, bins: Sequence[Sequence[float]], per_bin: int,
                 min_rotation_deg: float = 0.0,
                 usable: Callable[[int, int], bool] = lambda i, j: True
                 ) -> list[tuple[int, int, str]]:
  """Per distance bin (lo, hi metres between the two scans' positions), up to `per_bin`
  pairs (i < j, i, j, 'lo-hi m'), evenly spread over the bin's pairs ordered by distance:
  the pair at each of `per_bin` even steps, or where `usable(i, j)` is False the next
  usable one after it. Pairs turned less than `min_rotation_deg` apart are left out of
  bins starting at 0 m (a scan against one taken where it stood, not turned, is no test)."""
  out = []
  dist = np.linalg.norm(poses[:, None, :3, 3] - poses[None, :, :3, 3], axis=-1)
  for lo, hi in bins:
    cands = []
    for i, j in zip(*np.nonzero((dist >= lo) & (dist < hi))):
      if i >= j:
        continue
      turn = geometry.geodesic_angle_deg(np.eye(3), groundtruth.relative_pose(poses, i, j)[:3, :3])
      if lo == 0 and turn < min_rotation_deg:
        continue
      cands.append((dist[i, j], int(i), int(j)))
    cands.sort()
    chosen: list[tuple[int, int]] = []
    for start in np.linspace(0, len(cands), per_bin, endpoint=False).astype(int):
      for _, i, j in cands[max(start, 0):]:
        if (i, j) in chosen:
          continue
        if usable(i, j):
          chosen.append((i, j))
          break
    out += [(i, j, f'{lo:g}-{hi:g} m') for i, j in chosen]
  return out


def overlap(points1: np.ndarray, points2: np.ndarray, transform: np.ndarray,
            distance: float = OVERLAP_DISTANCE) -> float:
  """Share of points2 [M, 3] within `distance` metres of points1 [N, 3] under T_12."""
  moved = points2 @ transform[:3, :3].T + transform[:3, 3]
  d, _ = spatial.cKDTree(points1).query(moved, distance_upper_bound=distance)
  return float(np.mean(np.isfinite(d)))


def make_set(drive_folders: Sequence[str | os.PathLike], out: str | os.PathLike,
             bins: Sequence[Sequence[float]], per_bin: int = 8, seed: int = 0,
             turned: bool = True, min_rotation_deg: float = 20.0,
             min_overlap: float = MIN_OVERLAP,
             pose_holds: Callable[[np.ndarray, np.ndarray, np.ndarray], bool] | None = None,
             progress=None) -> list[dict]:
  """Writes a registration set (sequence-folder layout, `registration_sets`): OUT/%06d.bin
  (x y z + normals), OUT/groundtruths.txt and OUT/pairs.tsv whose `sensor2` is the drive
  and `overlap` the pair's measured overlap (pairs under `min_overlap` left out, as
  `choose_pairs`' unusable ones, and those where `pose_holds(scan i, scan j, T_12)` is
  False: a drive's poses are wrong where its SLAM ran away in a degenerate stretch). The
  scans are numbered drive after drive (scan s of the first drive is OUT/s, of the second
  OUT/(S1 + s), ...); the turned copy of cloud 2 at line n of groundtruths.txt follows them
  all (OUT/(S + n), S the scans of every drive) and draws its turn from
  `default_rng((seed, n))`. -> the pairs.tsv rows."""
  out = Path(out)
  out.mkdir(parents=True, exist_ok=True)
  drives = [read_drive(f) for f in drive_folders]
  first = np.cumsum([0] + [len(drive.scans) for drive in drives])   # each drive's first index
  rows, gts, read, written = [], [], {}, set()

  def scan(d: int, s: int, write: bool = False) -> np.ndarray:
    key = int(first[d]) + s
    if key not in read:
      path = drives[d].scans[s]
      read[key] = clean.clean_cloud(io.read_cloud(path), str(path), np.float64)
    if write and key not in written:
      _write(out / f'{key:06d}.bin', read[key])
      written.add(key)
    return read[key]

  shares = {}

  def share(d: int, i: int, j: int) -> float:
    if (d, i, j) not in shares:
      shares[d, i, j] = overlap(scan(d, i), scan(d, j),
                                groundtruth.relative_pose(drives[d].poses, i, j))
    return shares[d, i, j]

  for d, drive in enumerate(drives):
    def usable(i, j, d=d):
      return share(d, i, j) >= min_overlap and (pose_holds is None or pose_holds(
          scan(d, i), scan(d, j), groundtruth.relative_pose(drives[d].poses, i, j)))
    for i, j, _ in choose_pairs(drive.poses, bins, per_bin, min_rotation_deg, usable):
      t12 = groundtruth.relative_pose(drive.poses, i, j)
      cloud2 = scan(d, j, write=True)
      scan(d, i, write=True)
      views = [(int(first[d]) + j, t12, 'as driven')]
      if turned:
        yaw = 180.0 + np.random.default_rng((seed, len(gts))).uniform(-TURN_SPREAD_DEG,
                                                                        TURN_SPREAD_DEG)
        # cloud 2' = R cloud 2, so T_12' = T_12 R^-1
        turn = geometry.make_transform(geometry.rotation_z(np.radians(yaw)), np.zeros(3))
        idx = int(first[-1]) + len(gts)
        _write(out / f'{idx:06d}.bin', cloud2 @ turn[:3, :3].T)
        views.append((idx, t12 @ np.linalg.inv(turn), 'turned'))
      for idx2, t, heading in views:
        gts.append(groundtruth.GroundTruthPair(int(first[d]) + i, idx2, t))
        rows.append({'idx1': int(first[d]) + i, 'idx2': idx2, 'sensor1': drive.name,
                     'sensor2': drive.name, 'distance_m': float(np.linalg.norm(t12[:3, 3])),
                     'yaw_deg': float(geometry.yaw_deg(t)),
                     'source': f'{drive.name}/{i:06d}-{j:06d} {heading}',
                     'overlap': share(d, i, j)})
      if progress is not None:
        progress(1)
  groundtruth.write_groundtruths(out / 'groundtruths.txt', gts)
  registration_sets.write_pair_info(out, rows)
  return rows


def _write(path: Path, points: np.ndarray) -> None:
  """x y z + normals (`rescan`'s layout, which the reader tells apart from float64 rows)."""
  io.write_bin(path, points, preprocess.estimate_normals(points))
