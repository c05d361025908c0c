"""KITTI odometry (raw) -> 3DFeat-Net's processed registration set (docs/method.md §6).

Input: `sequences/XX/velodyne/%06d.bin` (N x 4), `sequences/XX/calib.txt` (line
`Tr:` = velodyne -> camera 0) and `poses/XX.txt` (camera-0 poses, one 3 x 4 per
line). The velodyne-frame pose is Tr^-1 · P_cam · Tr. A cloud is kept every
`spacing` metres of travel, voxel-gridded and given normals, and every two kept
clouds less than `pair_distance` apart form a pair with T_12 = T_1^-1 · T_2.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Callable

import numpy as np
from tqdm import auto as tqdm

from ssd_jax import geometry
from ssd_jax.data import groundtruth, io, preprocess
from ssd_jax.data.io import CloudFileError


def _rows_to_transforms(values: np.ndarray, path) -> np.ndarray:
  if values.ndim != 2 or values.shape[1] != 12:
    raise CloudFileError(f'{path}: expected 12 numbers (a row-major 3 x 4) per line')
  t = np.tile(np.eye(4), (len(values), 1, 1))
  t[:, :3, :] = values.reshape(-1, 3, 4)
  return t


def read_poses(path: str | os.PathLike) -> np.ndarray:
  """`poses/XX.txt` -> [P, 4, 4] float64."""
  path = Path(path)
  if not path.is_file():
    raise CloudFileError(f'{path}: no such pose file')
  return _rows_to_transforms(np.loadtxt(path, ndmin=2), path)


def read_velodyne_to_camera(calib_path: str | os.PathLike) -> np.ndarray:
  """The `Tr:` line of `calib.txt` -> [4, 4] velodyne -> camera-0 transform."""
  calib_path = Path(calib_path)
  if not calib_path.is_file():
    raise CloudFileError(f'{calib_path}: no such calibration file')
  for line in calib_path.read_text().splitlines():
    if line.startswith('Tr:'):
      return _rows_to_transforms(np.array([[float(v) for v in line[3:].split()]]), calib_path)[0]
  raise CloudFileError(f'{calib_path}: no "Tr:" line (velodyne -> camera transform)')


def velodyne_poses(camera_poses: np.ndarray, tr: np.ndarray) -> np.ndarray:
  """Camera-0 poses [P, 4, 4] -> velodyne poses Tr^-1 · P · Tr."""
  return geometry.invert_transform(tr) @ camera_poses @ tr


def write_poses(path: str | os.PathLike, poses: np.ndarray) -> None:
  """Poses [P, 4, 4] in the `poses/XX.txt` layout: one row-major 3 x 4 per line."""
  Path(path).write_text(''.join(' '.join(f'{v:.9e}' for v in p[:3].ravel()) + '\n'
                                for p in poses))


def keyframes(positions: np.ndarray, spacing: float) -> np.ndarray:
  """Indices of the frames kept when one is kept every `spacing` metres of travel."""
  kept, last = [0], positions[0]
  for i in range(1, len(positions)):
    if np.linalg.norm(positions[i] - last) >= spacing:
      kept.append(i)
      last = positions[i]
  return np.array(kept)


# (target cloud [N1, 3], source cloud [N2, 3], initial T_12 [4, 4]) -> (refined T_12, fitness)
Refine = Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, float]]


def process_sequence(root: str, seq: str, out: str, spacing: float = 10.0,
                     pair_distance: float = 10.0, voxel: float = 0.2, normal_radius: float = 1.0,
                     refine: Refine | None = None) -> tuple[int, int, list[dict]]:
  """One raw odometry sequence -> OUT/<seq>/: %06d.bin (N x 6: `voxel`-metre grid +
  normals within `normal_radius`), groundtruths.txt (pairs < `pair_distance` metres),
  poses.txt (velodyne-frame poses of the kept frames, one every `spacing` metres).

  With `refine` (e.g. registration.pipeline.refine_icp) each pair's pose is refined from
  KITTI's: groundtruths.txt then holds the refined pose, groundtruths_kitti.txt KITTI's,
  and icp_corrections.txt how far they differ. -> (clouds kept, pairs, [per-pair
  correction: idx1, idx2, fitness, rte (m), rre_geodesic (degrees)]).
  """
  tr = read_velodyne_to_camera(os.path.join(root, 'sequences', seq, 'calib.txt'))
  poses = velodyne_poses(read_poses(os.path.join(root, 'poses', f'{seq}.txt')), tr)
  kept = keyframes(poses[:, :3, 3], spacing)
  folder = os.path.join(out, seq)
  os.makedirs(folder, exist_ok=True)
  clouds = {}
  for i in tqdm.tqdm(kept, desc=f'sequence {seq}', unit='cloud'):
    raw = io.read_cloud(os.path.join(root, 'sequences', seq, 'velodyne', f'{i:06d}.bin'), 'xyzi')
    pts, normals = preprocess.process_scan(raw[np.all(np.isfinite(raw), 1)], voxel,
                                           normal_radius)
    io.write_bin(os.path.join(folder, f'{i:06d}.bin'), pts, normals)
    clouds[int(i)] = pts
  write_poses(os.path.join(folder, 'poses.txt'), poses[kept])
  pairs = [groundtruth.GroundTruthPair(int(kept[a]), int(kept[b]),
                                       groundtruth.relative_pose(poses, kept[a], kept[b]))
           for a, b in groundtruth.close_pairs(poses[kept, :3, 3], pair_distance)]
  corrections = []
  if refine is not None:
    groundtruth.write_groundtruths(os.path.join(folder, 'groundtruths_kitti.txt'), pairs)
    refined = []
    for p in pairs:
      t, fitness = refine(clouds[p.idx1], clouds[p.idx2], p.transform)
      refined.append(groundtruth.GroundTruthPair(p.idx1, p.idx2, t))
      corrections.append({
          'idx1': p.idx1, 'idx2': p.idx2, 'fitness': fitness,
          'rte': float(geometry.translation_error(p.transform[:3, 3], t[:3, 3])),
          'rre_geodesic': float(geometry.geodesic_angle_deg(p.transform[:3, :3], t[:3, :3]))})
    pairs = refined
    with open(os.path.join(folder, 'icp_corrections.txt'), 'w') as f:
      f.write('idx1\tidx2\tfitness\tdelta_t_m\tdelta_r_deg\n')
      for c in corrections:
        f.write(f'{c["idx1"]}\t{c["idx2"]}\t{c["fitness"]:.3f}\t{c["rte"]:.3f}\t'
                f'{c["rre_geodesic"]:.3f}\n')
  groundtruth.write_groundtruths(os.path.join(folder, 'groundtruths.txt'), pairs)
  return len(kept), len(pairs), corrections
