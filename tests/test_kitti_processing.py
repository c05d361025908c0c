"""KITTI raw-odometry processing, checked on synthetic scans written in KITTI's layout."""

import numpy as np
import pytest

from ssd_jax import geometry
from ssd_jax.data import groundtruth, io, kitti
from ssd_jax.registration import pair_stages
from ssd_jax.synthetic import dataset
from tests.conftest import tiny_synthetic_config as tiny_config

# KITTI-like velodyne -> camera: camera x right, y down, z forward.
TR = np.array([[0.0, -1.0, 0.0, 0.01], [0.0, 0.0, -1.0, -0.07], [1.0, 0.0, 0.0, -0.27],
               [0.0, 0.0, 0.0, 1.0]])


def test_processing_recovers_the_true_velodyne_poses(tmp_path):
  drive = dataset.make_drive(tiny_config(), 'test_kitti', 0)
  root = tmp_path / 'kitti'
  velo = root / 'sequences' / '00' / 'velodyne'
  velo.mkdir(parents=True)
  for k in range(len(drive.poses)):
    pts = drive.scan(k)
    np.concatenate([pts, np.zeros((len(pts), 1), np.float32)], 1).tofile(velo / f'{k:06d}.bin')
  cam = TR @ drive.poses @ geometry.invert_transform(TR)
  (root / 'poses').mkdir()
  np.savetxt(root / 'poses' / '00.txt', cam[:, :3].reshape(len(cam), 12))
  (root / 'sequences' / '00' / 'calib.txt').write_text(
      'P0: ' + ' '.join(['0'] * 12) + '\nTr: ' + ' '.join(f'{v:.12g}' for v in TR[:3].ravel()) + '\n')

  np.testing.assert_allclose(
      kitti.velodyne_poses(kitti.read_poses(root / 'poses' / '00.txt'),
                           kitti.read_velodyne_to_camera(root / 'sequences' / '00' / 'calib.txt')),
      drive.poses, atol=1e-9)
  n, m, corrections = kitti.process_sequence(str(root), '00', str(tmp_path / 'out'), 5.0, 10.0,
                                             0.2, 1.0, refine=pair_stages.refine_icp)
  assert len(drive.poses) - 2 <= n <= len(drive.poses) and m >= 5   # the U-turn may skip one
  out = tmp_path / 'out' / '00'
  for p in groundtruth.read_groundtruths(out / 'groundtruths_kitti.txt'):
    np.testing.assert_allclose(p.transform, groundtruth.relative_pose(drive.poses, p.idx1, p.idx2),
                               atol=1e-6)
  # the poses are exact here, so ICP barely moves them (a few cm; along a
  # corridor-like street up to ~0.1 m, which bounds what --icp can certify)
  rte = [c['rte'] for c in corrections]
  assert np.median(rte) < 0.05 and max(rte) < 0.25
  assert max(c['rre_geodesic'] for c in corrections) < 0.5
  assert io.read_cloud(out / '000000.bin').shape[0] > 1000


def test_keyframes_and_calibration_errors(tmp_path):
  pos = np.c_[np.arange(0, 35, 1.0), np.zeros(35), np.zeros(35)]
  np.testing.assert_array_equal(kitti.keyframes(pos, 10.0), [0, 10, 20, 30])
  (tmp_path / 'calib.txt').write_text('P0: 1 2 3\n')
  with pytest.raises(io.CloudFileError, match='no "Tr:" line'):
    kitti.read_velodyne_to_camera(tmp_path / 'calib.txt')
  (tmp_path / 'poses.txt').write_text('1 2 3\n')
  with pytest.raises(io.CloudFileError, match='12 numbers'):
    kitti.read_poses(tmp_path / 'poses.txt')
