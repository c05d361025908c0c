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

import numpy as np

from ssd_jax import geometry
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
