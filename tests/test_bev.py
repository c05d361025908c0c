"""The bird's-eye-view search: what its images hold, and the poses it finds."""

import numpy as np
import pytest

from ssd_jax import geometry
from ssd_jax.data import io
from ssd_jax.registration import bev, metrics, verification
from ssd_jax.registration import cloud_features, pair_stages, prepared
from tests.conftest import shared_path


def test_band_images_keep_what_rises_from_sloped_ground_and_drop_the_ground():
  """Ground rising 5 % along x (a hill: 2 m over 40 m) and a pole at (10, -5) rising
  0.55-3.45 m above its local ground (the lowest within ~6 m: 0.2 m, at x = 4). As cloud
  2 the pole is its structure and no ground point is; banded, its points from 1 m up,
  each in its band; as cloud 1 the pole fills the bands its heights reach
  (within BAND_MARGIN), there only within REACH of its cell, and the ground none."""
  x, y = np.meshgrid(np.arange(-20, 20, 0.2), np.arange(-20, 20, 0.2))
  ground = np.stack([x.ravel(), y.ravel(), 0.05 * x.ravel()], 1)
  heights = 0.55 + np.arange(30) * 0.1
  pole = np.stack([np.full(30, 10.0), np.full(30, -5.0), 0.2 + heights], 1)
  f = bev.footprint(np.concatenate([ground, pole]))
  rising, band = f.structure()   # the structure images': what rises HEIGHT above the ground
  assert len(rising) == 30 and not band.any()
  xy, band = f.structure(banded=True)
  np.testing.assert_allclose(xy + f.centre[:2], np.tile([10.0, -5.0], (len(xy), 1)))
  assert len(xy) == np.sum(heights >= 1.0) == 25
  np.testing.assert_array_equal(np.bincount(band), [15, 10])   # 1-2.5 m, 2.5-4 m
  images = bev.reach_images(f)
  size = bev._size(bev.EXTENT, bev.RESOLUTION)
  assert images.shape == (len(bev.BANDS) - 1, size, size)
  cell = np.floor((np.array([10.0, -5.0]) - f.centre[:2]) / bev.RESOLUTION).astype(int) + size // 2
  assert images[0][tuple(cell)] and images[1][tuple(cell)] and not images[2].any()
  filled = np.argwhere(images[0])
  assert np.abs(filled - cell).max() <= np.ceil(bev.REACH / bev.RESOLUTION)
  assert not bev.reach_images(bev.footprint(ground)).any()
  assert not len(bev.footprint(ground).structure()[0])
  assert not len(bev.footprint(ground).structure(banded=True)[0])


def _pair(yaw_deg: float, shift) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
  """A real KITTI scan within 50 m (cloud 1) and the scan seen from `shift` metres away at
  `yaw_deg`: half of its points, 3 cm noise, what lies within 50 m of the new standpoint
  (cloud 2) -> (cloud 1, cloud 2, T_12)."""
  scan = io.read_cloud(shared_path('kitti_object_velodyne', '000000.bin')).astype(np.float64)
  cloud1 = scan[np.linalg.norm(scan[:, :2], axis=1) < 50]
  t_true = geometry.make_transform(geometry.rotation_z(np.radians(yaw_deg)), np.asarray(shift))
  rng = np.random.default_rng(0)
  half = cloud1[::2]
  cloud2 = (half - t_true[:3, 3]) @ t_true[:3, :3] + rng.normal(0, 0.03, half.shape)
  return cloud1, cloud2[np.linalg.norm(cloud2[:, :2], axis=1) < 50], t_true


@pytest.mark.real_data
@pytest.mark.slow
def test_search_finds_a_pose_turned_and_shifted_anywhere_on_a_real_scan():
  cloud1, cloud2, t_true = _pair(137.0, [14.0, -9.0, 0.3])
  found = bev.search(cloud1, cloud2, k=3)
  assert found.transforms.shape == (3, 4, 4) and np.all(np.diff(found.scores) <= 0)
  err = metrics.registration_errors(t_true, found.transforms[0])
  # Half a yaw step and half a cell (the z shift is ICP's to find).
  assert err['rre_geodesic'] < bev.YAW_STEP / 2 + 0.1
  assert np.linalg.norm(found.transforms[0][:2, 3] - t_true[:2, 3]) < bev.RESOLUTION
  np.testing.assert_array_equal(found.transforms, bev.search(cloud1, cloud2, k=3).transforms)
  with pytest.raises(ValueError, match='yaw_step > 0'):
    bev.search(cloud1, cloud2, yaw_step=0)


@pytest.mark.real_data
@pytest.mark.slow
def test_banded_search_and_its_ranked_poses_find_a_pose_turned_and_shifted_on_a_real_scan():
  """The banded scoring finds the turned and shifted scan as the structure images do, and
  its poses ranked as the verification picks (the 'bev' retry's) start with it."""
  cloud1, cloud2, t_true = _pair(137.0, [14.0, -9.0, 0.3])
  found = bev.search(cloud1, cloud2, k=3, banded=True)
  assert np.all(np.diff(found.scores) <= 0)
  ranked = prepared.PreparedPair(cloud1, cloud2).bev_poses(3, banded=True)
  assert ranked.shape == (3, 4, 4)
  for pose in (found.transforms[0], ranked[0]):
    assert metrics.registration_errors(t_true, pose)['rre_geodesic'] < bev.YAW_STEP / 2 + 0.1
    assert np.linalg.norm(pose[:2, 3] - t_true[:2, 3]) < bev.RESOLUTION


@pytest.mark.real_data
def test_search_is_unchanged_by_points_no_yaw_brings_into_the_image():
  """Walls 130-140 m from cloud 2's centre (a map tile's far side; the image's corners are
  extent * sqrt(2) = 90.5 m away) leave every pose and score as they were."""
  cloud1, cloud2, _ = _pair(137.0, [14.0, -9.0, 0.3])
  centre = np.append(np.median(cloud2[:, :2], 0), 0.0)
  wall = np.stack(np.meshgrid(np.arange(0, 10, 0.2), [0.0], np.arange(0, 3, 0.2)), -1)
  # One wall past each corner: every coordinate's median stays where it was.
  far = [wall.reshape(-1, 3) + centre + [sx * 95.0, sy * 95.0, 0.0]
         for sx in (-1, 1) for sy in (-1, 1)]
  plain = bev.search(cloud1, cloud2, k=3, yaw_step=30.0)
  tiled = bev.search(cloud1, np.concatenate([cloud2, *far]), k=3, yaw_step=30.0)
  np.testing.assert_array_equal(plain.transforms, tiled.transforms)
  np.testing.assert_array_equal(plain.scores, tiled.scores)


@pytest.mark.real_data
@pytest.mark.slow
def test_search_and_verification_use_a_stride_of_a_cloud_past_their_budgets(monkeypatch):
  """A map tile's grid is imaged and aligned to on an even stride of its points
  (bev.MAX_POINTS, verification.TARGET_POINTS): with both a quarter of the scan, the BEV
  search's best pose is as close and the verified pose as exact as on every point."""
  cloud1, cloud2, t_true = _pair(137.0, [14.0, -9.0, 0.3])
  monkeypatch.setattr(bev, 'MAX_POINTS', len(cloud2) // 4)
  monkeypatch.setattr(verification, 'TARGET_POINTS', len(cloud1) // 4)
  found = bev.search(cloud1, cloud2, k=3)
  assert metrics.registration_errors(t_true, found.transforms[0])['rre_geodesic'] < (
      bev.YAW_STEP / 2 + 0.1)
  assert np.linalg.norm(found.transforms[0][:2, 3] - t_true[:2, 3]) < bev.RESOLUTION
  best, refined, _ = verification.verify(cloud1, cloud2, found.transforms)
  err = metrics.registration_errors(t_true, refined[best])
  assert err['rte'] < 0.1 and err['rre_geodesic'] < 0.3, err


@pytest.mark.real_data
@pytest.mark.slow
def test_verification_with_bev_candidates_registers_where_every_ransac_pose_is_wrong():
  """RANSAC's candidates all 8 m off; the BEV search's poses join the check, and the
  verified pose is exact."""
  cloud1, cloud2, t_true = _pair(-65.0, [-20.0, 6.0, 0.0])
  wrong = np.stack([t_true @ geometry.make_transform(geometry.rotation_z(a), np.array([8.0, 0, 0]))
                    for a in (0.0, 0.5, 1.0)])
  f = cloud_features.CloudFeatures(cloud2[:10], np.eye(10), {})
  reg = pair_stages.Registration(wrong[0], np.stack([np.arange(10)] * 2, 1), np.zeros(10, bool),
                                 0, {}, candidates=wrong)
  assert not metrics.registration_errors(t_true, pair_stages.verify(reg, f, f, cloud1,
                                                                    cloud2).transform)['success']
  verified = pair_stages.verify(reg, f, f, cloud1, cloud2, bev_candidates=3)
  assert len(verified.verified_fitness) == 6 and verified.seconds['bev'] > 0
  err = metrics.registration_errors(t_true, verified.transform)
  assert err['rte'] < 0.1 and err['rre_geodesic'] < 0.3, err


@pytest.mark.real_data
def test_a_ransac_pose_that_fits_confidently_is_taken_without_the_bev_search(monkeypatch):
  """RANSAC's candidates hold the true pose (0.3 m off) beside two 8 m off: it lays more
  than CONFIDENT_FITNESS of cloud 2 on cloud 1, so the BEV search is not run, and the
  answer is the one verifying RANSAC's candidates alone gives."""
  cloud1, cloud2, t_true = _pair(-65.0, [-20.0, 6.0, 0.0])
  off = lambda d: t_true @ geometry.make_transform(np.eye(3), np.array([d, 0.0, 0.0]))
  candidates = np.stack([off(8.0), off(0.3), off(-8.0)])
  f = cloud_features.CloudFeatures(cloud2[:10], np.eye(10), {})
  reg = pair_stages.Registration(candidates[0], np.stack([np.arange(10)] * 2, 1),
                                 np.zeros(10, bool), 0, {}, candidates=candidates)
  searches = []
  original = bev.search
  monkeypatch.setattr(bev, 'search', lambda *a, **k: searches.append(1) or original(*a, **k))
  verified = pair_stages.verify(reg, f, f, cloud1, cloud2, bev_candidates=5)
  assert not searches and len(verified.verified_fitness) == 3
  assert verified.verified_fitness.max() >= verification.CONFIDENT_FITNESS
  assert verified.seconds['bev'] == 0.0
  np.testing.assert_array_equal(verified.transform,
                                pair_stages.verify(reg, f, f, cloud1, cloud2).transform)
  assert metrics.registration_errors(t_true, verified.transform)['rte'] < 0.1


def _box(cx: float, cy: float, size=(2.0, 1.0, 1.6), step: float = 0.2) -> np.ndarray:
  """The sides and top of a car-sized box standing on the ground at (cx, cy), sampled on
  a `step` grid."""
  sx, sy, sz = size
  xs, ys, zs = (np.arange(-s / 2, s / 2 + 1e-6, step) for s in size)
  gx, gz = np.meshgrid(xs, zs)
  gy, hz = np.meshgrid(ys, zs)
  tx, ty = np.meshgrid(xs, ys)
  faces = [np.column_stack([gx.ravel(), np.full(gx.size, side), gz.ravel() + sz / 2])
           for side in (-sy / 2, sy / 2)]
  faces += [np.column_stack([np.full(gy.size, side), gy.ravel(), hz.ravel() + sz / 2])
            for side in (-sx / 2, sx / 2)]
  faces.append(np.column_stack([tx.ravel(), ty.ravel(), np.full(tx.size, sz)]))
  return np.concatenate(faces) + np.array([cx, cy, 0.05 + sz / 2])


def test_verification_scores_what_rises_from_the_ground():
  """A street on a 0.2 m grid: ground, a facade, five parked cars; cloud 2 is its middle
  24 m. A pose 8 m along the street lays cloud 2's ground and facade as well as the true
  pose: scored on every point the two are nearly tied (the ground is most of the cloud);
  scored on what rises from the ground, the cars tell them apart."""
  x, y = np.meshgrid(np.arange(-30, 30, 0.2), np.arange(-30, 30, 0.2))
  ground = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
  xw, zw = np.meshgrid(np.arange(-30, 30, 0.2), np.arange(0.2, 5, 0.2))
  facade = np.column_stack([xw.ravel(), np.full(xw.size, 8.0), zw.ravel()])
  cars = np.concatenate([_box(x, 4.0) for x in (-16, -9, -1, 5, 14)])
  cloud1 = np.concatenate([ground, facade, cars])
  middle = cloud1[np.abs(cloud1[:, 0]) < 12]
  cloud2 = middle + np.random.default_rng(0).normal(0, 0.02, middle.shape)   # T_12 = I
  along = geometry.make_transform(np.eye(3), np.array([10.0, 0.0, 0.0]))
  candidates = np.stack([along, np.eye(4)])
  _, _, on_all = verification.verify(cloud1, cloud2, candidates, score_on='all')
  best, refined, rising = verification.verify(cloud1, cloud2, candidates)
  assert on_all[1] - on_all[0] < 0.02                      # nearly tied on every point
  assert best == 1 and rising[1] - rising[0] > 5 * (on_all[1] - on_all[0])
  assert np.abs(refined[1] - np.eye(4)).max() < 0.02
  assert np.linalg.norm(refined[0][:3, 3]) > 5.0            # still a pose along the street
  with pytest.raises(ValueError, match="score_on must be 'rising' or 'all'"):
    verification.verify(cloud1, cloud2, candidates, score_on='ground')


def test_a_cloud_with_little_structure_is_scored_on_all_its_points(monkeypatch):
  """Rolling ground and three thin poles, which stand 1.5 m elsewhere in cloud 2: fewer
  than MIN_RISING_POINTS points rise from it, so the structure score falls back to every
  point (the ground fits); with a lower minimum it is the poles' share alone (none fit)."""
  x, y = np.meshgrid(np.arange(-20, 20, 0.2), np.arange(-20, 20, 0.2))
  ground = np.column_stack([x.ravel(), y.ravel(),
                            0.15 * np.sin(x.ravel() / 3) * np.cos(y.ravel() / 4)])
  poles = np.concatenate([np.column_stack([np.full(20, px), np.full(20, py),
                                           np.arange(1.0, 5.0, 0.2)])
                          for px, py in ((-10, 5), (3, -7), (12, 9))])
  cloud1 = np.concatenate([ground, poles])
  cloud2 = np.concatenate([ground, poles + np.array([1.5, 0.0, 0.0])])
  assert bev.rising_from_ground(cloud2).sum() < verification.MIN_RISING_POINTS
  candidates = np.eye(4)[None]
  _, _, on_all = verification.verify(cloud1, cloud2, candidates, score_on='all')
  _, _, fallback = verification.verify(cloud1, cloud2, candidates)
  assert on_all[0] > 0.99
  np.testing.assert_allclose(fallback, on_all)
  monkeypatch.setattr(verification, 'MIN_RISING_POINTS', 10)
  _, _, on_poles = verification.verify(cloud1, cloud2, candidates)
  assert on_poles[0] == 0.0
