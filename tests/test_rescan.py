"""Re-scan pairs from single real scans (ssd_jax.data.rescan)."""

import os
import subprocess
import sys

import numpy as np
import pytest
from scipy import spatial

from ssd_jax import geometry, sensors
from ssd_jax.data import datasets, io, registration_sets, rescan
from ssd_jax.evaluation import registration
from tests.conftest import shared_path


@pytest.mark.real_data
def test_rescan_pair_is_a_different_sampling_that_the_transform_aligns():
  points = io.read_cloud(shared_path('example', 'oxford_270.bin'))
  cloud1, cloud2, t12 = rescan.rescan_pair(np.random.default_rng(0), points, 130.0)
  assert abs(geometry.yaw_deg(t12) - 130.0) < 1e-9
  assert 2.0 <= np.linalg.norm(t12[:2, 3]) <= 10.0 and t12[2, 3] == 0
  moved = cloud2 @ t12[:3, :3].T + t12[:3, 3]
  dist, _ = spatial.cKDTree(cloud1).query(moved)
  assert np.median(dist) < 0.1                       # the same surfaces ...
  assert np.mean(dist < 1e-3) < 0.01                 # ... but no shared points
  assert 0.2 * len(cloud1) < len(cloud2) < 0.9 * len(cloud1)   # the other view sees less
  # Without the transform the clouds do not line up (the test can fail).
  assert np.median(spatial.cKDTree(cloud1).query(cloud2)[0]) > 0.3


@pytest.mark.real_data
def test_a_tilted_rescan_is_seen_by_a_unit_tilted_within_the_range():
  """cfg.tilt: the second view's sensor is tilted (about a horizontal axis) by an angle in
  the range, T_12 holds the tilt and the yaw, and still aligns the two views."""
  points = io.read_cloud(shared_path('kitti_object_velodyne', '000000.bin'))
  cfg = rescan.RescanConfig(tilt=(10.0, 30.0))
  for seed in range(3):
    cloud1, cloud2, t12 = rescan.rescan_pair(np.random.default_rng(seed), points, 70.0, cfg)
    tilt = np.degrees(np.arccos(t12[2, 2]))                    # of the sensor's z axis
    assert 10.0 - 1e-6 <= tilt <= 30.0 + 1e-6, tilt
    moved = cloud2 @ t12[:3, :3].T + t12[:3, 3]
    assert np.median(spatial.cKDTree(cloud1).query(moved)[0]) < 0.1
  # No tilt asked for: the draws, and the pair, are those of an untilted set.
  plain = rescan.rescan_pair(np.random.default_rng(0), points, 70.0, rescan.RescanConfig())
  again = rescan.rescan_pair(np.random.default_rng(0), points, 70.0,
                             rescan.RescanConfig(tilt=(0.0, 0.0)))
  np.testing.assert_array_equal(plain[2], again[2])


@pytest.mark.real_data
def test_second_submap_keeps_what_a_sensor_would_not_see():
  """Submap pairs (occlusion off): the second view is the whole place within max_range
  of a displaced centre, not what a sensor there would see."""
  points = io.read_cloud(shared_path('example', 'oxford_270.bin'))
  cfg = rescan.RescanConfig(max_range=30.0, occlusion=False)
  cloud1, cloud2, t12 = rescan.rescan_pair(np.random.default_rng(0), points, 130.0, cfg)
  occluded = rescan.rescan_pair(np.random.default_rng(0), points, 130.0,
                                rescan.RescanConfig(max_range=30.0))[1]
  assert np.linalg.norm(cloud2[:, :2], axis=1).max() <= 30.0 + 0.2   # grid + noise
  assert len(cloud2) > 0.8 * len(cloud1) and len(cloud2) > 1.5 * len(occluded)
  moved = cloud2 @ t12[:3, :3].T + t12[:3, 3]
  dist, _ = spatial.cKDTree(cloud1).query(moved)
  assert np.median(dist) < 0.1 and np.mean(dist < 1e-3) < 0.01
  # Every second-view point lies within 30 m of the displaced centre in cloud 1's frame.
  assert np.linalg.norm(moved[:, :2] - t12[:2, 3], axis=1).max() <= 30.0 + 0.2


@pytest.mark.real_data
def test_rescan_set_is_deterministic_and_covers_every_yaw_bin(tmp_path):
  sources = [shared_path('kitti_object_velodyne', '000000.bin')]
  rows = rescan.make_rescan_set(sources, tmp_path / 'a', seed=3, pairs_per_cloud=8)
  rescan.make_rescan_set(sources, tmp_path / 'b', seed=3, pairs_per_cloud=8)
  assert (tmp_path / 'a' / 'groundtruths.txt').read_text() == \
      (tmp_path / 'b' / 'groundtruths.txt').read_text()
  assert (tmp_path / 'a' / '000003.bin').read_bytes() == (tmp_path / 'b' / '000003.bin').read_bytes()
  yaws = np.array([r['yaw_deg'] for r in rows])
  np.testing.assert_array_equal(np.sort(np.floor((yaws + 180) / 45)), np.arange(8))
  pairs = registration_sets.read_registration_set(tmp_path / 'a')
  assert len(pairs) == 8
  bins = [registration.yaw_bin(registration.relative_yaw_deg(p.transform)) for p in pairs]
  assert sorted(bins) == [0, 0, 1, 1, 2, 2, 3, 3]


@pytest.mark.real_data
@pytest.mark.multiprocess
def test_make_real_pairs_command_submaps_and_bad_flags(tmp_path):
  real = shared_path()
  run = lambda *args: subprocess.run(
      [sys.executable, '-m', 'experiments.data.make_real_pairs', f'--real={real}', *args],
      capture_output=True, text=True, cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
  out = run('--sources=example/oxford_*.bin', '--submaps', '--max_range=30',
            '--pairs_per_cloud=2', f'--out={tmp_path / "sub"}')
  assert out.returncode == 0, out.stderr[-2000:]
  sources = (tmp_path / 'sub' / 'sources.tsv').read_text().splitlines()[1:]
  assert len(sources) == 4 and all('\toxford_' in line for line in sources)
  out = run('--sources=nothing/*.bin', f'--out={tmp_path / "x"}')
  assert out.returncode == 1 and 'no scans match nothing/*.bin' in out.stderr
  out = run('--max_range=0', f'--out={tmp_path / "y"}')
  assert out.returncode == 1 and '--max_range must be > 0' in out.stderr
  assert 'Traceback' not in out.stderr
  for tilt in ('30,10', 'a,b', '5'):
    out = run(f'--tilt={tilt}', f'--out={tmp_path / "z"}')
    assert out.returncode == 1 and '--tilt must be lo,hi degrees' in out.stderr, out.stderr
    assert 'Traceback' not in out.stderr


@pytest.mark.real_data
def test_rescan_view_is_another_unit_in_the_scans_own_frame():
  points = io.read_cloud(shared_path('kitti_object_velodyne', '000000.bin'))
  cfg = rescan.RescanConfig(min_shift=5.0, max_shift=10.0, sensor='vlp16', min_points=500,
                            toward_points=True)
  view = rescan.rescan_view(np.random.default_rng(0), points, cfg)
  again = rescan.rescan_view(np.random.default_rng(0), points, cfg)
  np.testing.assert_array_equal(view, again)
  assert view.dtype == np.float32 and 500 <= len(view) < 0.5 * len(points)
  # No transform: the view lies on the scan's surfaces where it stands ...
  dist, _ = spatial.cKDTree(points).query(view)
  assert np.median(dist) < 0.15
  # ... and a 16-beam unit 5-10 m away sees other rings: the scan's nearest-neighbour
  # structure is not kept (fewer points per ring, the scan's own rings elsewhere).
  own = np.median(spatial.cKDTree(points).query(points, k=2)[0][:, 1])
  assert np.median(spatial.cKDTree(view).query(view, k=2)[0][:, 1]) > own


@pytest.mark.real_data
def test_a_cast_rescan_lies_on_the_scans_surfaces_on_the_units_rings():
  points = io.read_cloud(shared_path('kitti_object_velodyne', '000000.bin'))
  cfg = rescan.RescanConfig(min_shift=5.0, max_shift=10.0, sensor='vlp16', min_points=500,
                            toward_points=True, noise_sigma=0.0, voxel_size=0.01,
                            beams='cast')
  view, transform = rescan._virtual_scan(np.random.default_rng(0), points, 30.0, cfg)
  # In the unit's frame its points lie on its 16 beams (0.01 m voxels move them little) ...
  el = np.degrees(np.arctan2(view[:, 2], np.linalg.norm(view[:, :2], axis=1)))
  off = np.min(np.abs(el[:, None] - sensors.get('vlp16').elevations()), axis=1)
  assert len(view) >= 500 and np.median(off) < 0.05
  # ... and, moved back, on the scan's surfaces.
  back = view @ transform[:3, :3].T + transform[:3, 3]
  assert np.median(spatial.cKDTree(points).query(back)[0]) < 0.15
  with pytest.raises(ValueError, match=r"beams must be one of \('select', 'cast'\)"):
    rescan.RescanConfig(beams='trace')
  with pytest.raises(ValueError, match='name the unit'):
    rescan.RescanConfig(beams='cast')


@pytest.mark.real_data
def test_rescan_pair_dataset_pairs_a_cloud_with_its_rescan_or_itself(tmp_path):
  source = shared_path('kitti_object_velodyne', '000000.bin')
  kwargs = dict(sensors=('vlp16', 'hdl32'), min_shift=5.0, max_shift=10.0, views_per_cloud=2,
                crop_radius=20.0)
  always = datasets.RescanPairDataset([source], rate=1.0, **kwargs)
  never = datasets.RescanPairDataset([source], rate=0.0, **kwargs)
  b = always.batch(0, 0, 2, 1024)
  assert b.shape == (2, 2, 1024, 3) and b.dtype == np.float32
  np.testing.assert_array_equal(b, always.batch(0, 0, 2, 1024))     # a function of the step
  assert not np.array_equal(b[0, 0], b[0, 1])
  assert np.linalg.norm(b[:, 1], axis=-1).max() <= 20.0             # the same disk
  dist, _ = spatial.cKDTree(always.clouds.cloud(0)).query(b[0, 1])
  assert np.median(dist) < 0.15                                      # in the cloud's frame
  c = never.batch(0, 0, 2, 1024)
  np.testing.assert_array_equal(c[:, 0], c[:, 1])                   # the paper's pair
  np.testing.assert_array_equal(c[:, 0], b[:, 0])
