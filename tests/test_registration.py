"""Ground-truth files, RANSAC and registration metrics."""

import dataclasses

import numpy as np
import pytest
from scipy import spatial

from ssd_jax import geometry
from ssd_jax.data import clean, groundtruth, io, registration_sets
from ssd_jax.evaluation import registration
from ssd_jax.registration import features, keypoints, matching, metrics, pipeline, ransac
from ssd_jax.registration import cloud_features, pair_stages
from ssd_jax.registration import options as options_lib
from ssd_jax.evaluation import reference
from ssd_jax.synthetic import trajectory
from tests.conftest import shared_path


def test_reads_reference_groundtruths(tmp_path):
  c = np.cos(np.pi / 4)
  (tmp_path / 'groundtruths.txt').write_text(
      'idx1\tidx2\tt_1\tt_2\tt_3\tq_1\tq_2\tq_3\tq_4\n'
      f'270\t456\t1.5\t-2.0\t0.25\t{c}\t0\t0\t{c}\n')
  (pair,) = groundtruth.read_groundtruths(tmp_path / 'groundtruths.txt')
  assert (pair.idx1, pair.idx2) == (270, 456)
  expected = np.array([[0, -1, 0, 1.5], [1, 0, 0, -2.0], [0, 0, 1, 0.25], [0, 0, 0, 1]])
  np.testing.assert_allclose(pair.transform, expected, atol=1e-12)


def test_groundtruths_round_trip_and_errors(tmp_path):
  rng = np.random.default_rng(0)
  pairs = []
  for i in range(5):
    rot = trajectory.rotation_zyx(*rng.uniform(-np.pi, np.pi, 3))
    pairs.append(groundtruth.GroundTruthPair(i, i + 1, geometry.make_transform(rot, rng.normal(size=3) * 5)))
  path = tmp_path / 'gt.txt'
  groundtruth.write_groundtruths(path, pairs)
  assert path.read_text().splitlines()[0] == 'idx1\tidx2\tt_1\tt_2\tt_3\tq_1\tq_2\tq_3\tq_4'
  back = groundtruth.read_groundtruths(path)
  for a, b in zip(pairs, back):
    assert (a.idx1, a.idx2) == (b.idx1, b.idx2)
    np.testing.assert_allclose(a.transform, b.transform, atol=1e-8)
  (tmp_path / 'bad.txt').write_text('0 1 0 0 0 1 0 0\n')
  with pytest.raises(io.CloudFileError, match=r'bad.txt:1: expected 9 fields'):
    groundtruth.read_groundtruths(tmp_path / 'bad.txt')
  (tmp_path / 'bad.txt').write_text('0 1 0 0 0 2 0 0 0\n')
  with pytest.raises(io.CloudFileError, match='not a finite unit quaternion'):
    groundtruth.read_groundtruths(tmp_path / 'bad.txt')
  with pytest.raises(io.CloudFileError, match='no such ground-truth file'):
    groundtruth.read_groundtruths(tmp_path / 'missing.txt')


def _noisy_correspondences(rng, n, outlier_fraction):
  t_12 = geometry.make_transform(trajectory.rotation_zyx(2.0, 0.03, -0.02),
                                 np.array([4.0, -3.0, 0.2]))
  xyz2 = rng.uniform(-30, 30, (n, 3))
  xyz1 = geometry.apply_transform(t_12, xyz2) + rng.normal(0, 0.05, (n, 3))
  outliers = rng.permutation(n)[: int(outlier_fraction * n)]
  xyz1[outliers] = rng.uniform(-30, 30, (len(outliers), 3))
  truth = np.ones(n, bool)
  truth[outliers] = False
  return t_12, xyz1, xyz2, truth


@pytest.mark.parametrize('outlier_fraction', [0.5, 0.9])
def test_ransac_recovers_known_transform(outlier_fraction):
  t_12, xyz1, xyz2, truth = _noisy_correspondences(np.random.default_rng(1), 300, outlier_fraction)
  samples = ransac.draw_minimal_samples(np.random.default_rng(2), xyz2, 10_001)
  for result in (ransac.ransac(xyz1, xyz2, samples), ransac.ransac_sequential(xyz1, xyz2, samples)):
    err = metrics.registration_errors(t_12, result.transform)
    assert err['rte'] < 0.05 and err['rre_geodesic'] < 0.2
    assert (result.inliers & truth).sum() >= 0.95 * truth.sum()
    # the adaptive rule stopped near log(0.01) / log(1 - w^3), far below the cap
    w = result.inliers.mean()
    assert 10 <= result.trials <= 3 * np.log(0.01) / np.log(1 - w ** 3) + 10


@pytest.mark.parametrize('seed,outlier_fraction,n', [(0, 0.5, 100), (1, 0.8, 250), (2, 0.9, 300),
                                                     (3, 0.97, 500), (4, 1.0, 40),
                                                     (5, 0.9, 1500)])   # smaller batches
def test_batched_ransac_trial_count_equals_sequential_rule(seed, outlier_fraction, n):
  """Same minimal samples => same stopping point, trial count, inliers and model;
  fully random matches run into the cap (10,001 trials)."""
  _, xyz1, xyz2, _ = _noisy_correspondences(np.random.default_rng(seed), n, outlier_fraction)
  samples = ransac.draw_minimal_samples(np.random.default_rng(seed + 10), xyz2, 10_001)
  seq = ransac.ransac_sequential(xyz1, xyz2, samples)
  par = ransac.ransac(xyz1, xyz2, samples, batch_size=128)
  assert par.trials == seq.trials
  np.testing.assert_array_equal(par.inliers, seq.inliers)
  np.testing.assert_allclose(par.transform, seq.transform, atol=1e-9)
  if outlier_fraction == 1.0:
    assert seq.trials == 10_001


def test_ransac_scores_only_the_batches_the_rule_needs(monkeypatch):
  """An easy pair stops after a few dozen trials: one first batch of 32 is scored,
  not a full batch of 512; the batches then double."""
  _, xyz1, xyz2, _ = _noisy_correspondences(np.random.default_rng(0), 200, 0.3)
  samples = ransac.draw_minimal_samples(np.random.default_rng(1), xyz2, 10_001)
  sizes = []
  scorer = ransac._numpy_scorer
  monkeypatch.setattr(ransac, '_numpy_scorer', lambda *a: (
      lambda batch: sizes.append(len(batch)) or scorer(*a)(batch)))
  assert ransac.ransac(xyz1, xyz2, samples).trials <= 32
  assert sizes == [32]
  _, xyz1, xyz2, _ = _noisy_correspondences(np.random.default_rng(0), 200, 0.9)
  sizes.clear()
  samples = ransac.draw_minimal_samples(np.random.default_rng(1), xyz2, 10_001)
  trials = ransac.ransac(xyz1, xyz2, samples).trials
  assert sizes[:5] == [32, 64, 128, 256, 512] and sum(sizes[:-1]) < trials <= sum(sizes)


def test_minimal_samples_are_distinct_and_not_collinear():
  xyz = np.zeros((50, 3))
  xyz[:, 0] = np.arange(50)     # all collinear except the last point
  xyz[-1] = [0.0, 5.0, 0.0]
  samples = ransac.draw_minimal_samples(np.random.default_rng(0), xyz, 200)
  assert samples.shape == (200, 3)
  assert np.all((samples == 49).any(1))
  assert all(len(set(s)) == 3 for s in samples.tolist())
  with pytest.raises(ValueError, match='collinear'):
    ransac.draw_minimal_samples(np.random.default_rng(0), xyz[:-1], 10)


def test_registration_metrics_hand_computed():
  rz3 = geometry.make_transform(trajectory.rotation_zyx(np.radians(3.0), 0.0, 0.0),
                                np.array([1.0, 0.0, 0.0]))
  e = metrics.registration_errors(np.eye(4), rz3)
  assert e['rte'] == pytest.approx(1.0) and e['rre'] == pytest.approx(3.0)
  assert e['rre_geodesic'] == pytest.approx(3.0) and e['success']
  # Euler-sum RRE adds |z| + |y| + |x| = 3 + 0 + 2 = 5 degrees: not a success (< 5 needed)
  both = geometry.make_transform(trajectory.rotation_zyx(np.radians(3.0), 0.0, np.radians(2.0)),
                                 np.zeros(3))
  e = metrics.registration_errors(np.eye(4), both)
  assert e['rre'] == pytest.approx(5.0) and not e['success']
  assert e['rre_geodesic'] == pytest.approx(np.degrees(np.arccos(
      (np.trace(both[:3, :3]) - 1) / 2)))
  s = registration.summarize([
      {'rte': 1.0, 'rre': 1.0, 'rre_geodesic': 1.0, 'success': True, 'trials': 10},
      {'rte': 9.0, 'rre': 90.0, 'rre_geodesic': 90.0, 'success': False, 'trials': 30}])
  assert s == {'pairs': 2, 'rte': 1.0, 'rre': 1.0, 'rre_geodesic': 1.0, 'success_rate': 0.5,
               'trials': 20.0}


def test_ransac_refuses_too_few_samples():
  _, xyz1, xyz2, _ = _noisy_correspondences(np.random.default_rng(0), 50, 0.5)
  samples = ransac.draw_minimal_samples(np.random.default_rng(0), xyz2, 100)
  for fn in (ransac.ransac, ransac.ransac_sequential):
    with pytest.raises(ValueError, match='max_trials \\+ 1 = 10001 trials but got 100 samples'):
      fn(xyz1, xyz2, samples)


def test_fpfh_follows_the_keypoint_order():
  """Open3D returns features in ascending index order; learned keypoints come strongest
  first, so the wrapper must map them back (a bug that once zeroed the learned-keypoint
  + FPFH rows)."""
  pts = np.random.default_rng(0).normal(size=(2000, 3)) * 5
  idx = np.array([500, 3, 1200, 7, 3])
  ordered = features.fpfh(pts, idx, radius=2.0)
  ref = features.fpfh(pts, np.array([3, 7, 500, 1200]), radius=2.0)
  np.testing.assert_array_equal(ordered, ref[[2, 0, 3, 1, 0]])
  assert np.abs(ref[0] - ref[1]).sum() > 1.0


def test_register_far_from_origin_is_as_accurate_as_near_it(synthetic_root):
  """UTM-scale float64 clouds are centred in float64 before any float32 step, each on its
  centroid: the pair registers as accurately at x = 4.5e5, y = 5.4e6 as near the origin,
  and T comes back in the caller's coordinates. Clouds near the origin are not shifted."""
  pair = registration_sets.read_registration_set(synthetic_root / 'test_kitti')[0]
  c1, c2 = (io.read_cloud(p).astype(np.float64) for p in (pair.cloud1, pair.cloud2))
  # As scanned (sensor at the origin): exactly the stage-by-stage result, no shift.
  reg, _, _ = pipeline.register(target=c1, source=c2,
                                options=options_lib.Options.paper(fpfh_max_nn=200))
  staged = pair_stages.estimate(cloud_features.cloud_features(c1, fpfh_max_nn=200),
                                cloud_features.cloud_features(c2, fpfh_max_nn=200))
  np.testing.assert_allclose(reg.transform, staged.transform, atol=1e-9)
  assert metrics.registration_errors(pair.transform, reg.transform)['success']
  centre = c1.mean(axis=0)
  errors = []
  for offset in (-centre, np.array([4.5e5, 5.4e6, 30.0]) - centre):
    shift = geometry.make_transform(np.eye(3), offset)
    t_gt = shift @ pair.transform @ geometry.invert_transform(shift)
    reg, f1, _ = pipeline.register(target=c1 + offset, source=c2 + offset,
                                   options=options_lib.Options.paper(fpfh_max_nn=200))
    moved = lambda t: (c2 + offset) @ t[:3, :3].T + t[:3, 3]
    errors.append(np.linalg.norm(moved(reg.transform) - moved(t_gt), axis=1))
    assert np.abs(f1.xyz - offset).max() < 100   # keypoints in the caller's coordinates
  near, far = errors
  assert np.median(near) < 0.5, np.median(near)
  assert abs(np.percentile(far, 95) - np.percentile(near, 95)) < 0.05, (far, near)


def test_pipeline_refuses_bad_clouds_with_one_line():
  pts = np.random.default_rng(0).normal(size=(500, 3)) * 5
  with_nan = pts.copy()
  with_nan[3] = np.nan
  for bad, message in ((with_nan, '1 points have NaN/Inf'), (np.zeros((0, 3)), 'empty'),
                       (pts[:, :2], r'shape \[N, 3\]'),
                       (pts + 5.4e6, 'float32 resolves only 0.5 m; subtract an offset'),
                       (pts[:5], r'iss keypoints: found a cloud of 5 points, 64')):
    with pytest.raises(ValueError, match=message):
      cloud_features.cloud_features(bad, fpfh_max_nn=50)
  for idx in (np.array([0, 500]), np.array([[1, 2]]), np.array([0.5])):
    with pytest.raises(ValueError, match='keypoint_idx must be'):
      cloud_features.compute_descriptors(pts, idx, 'fpfh')
  # Coordinates that even their own file type cannot resolve: said so, not "degenerate".
  with pytest.raises(clean.CloudDataError, match='float32 resolves only 64 m; store it'):
    clean.clean_cloud((pts + 1e9).astype(np.float32), 'far')
  far = clean.clean_cloud(pts + 1e9, 'far', np.float64)
  assert far.dtype == np.float64 and np.ptp(far - 1e9) > 10


def test_open3d_reference_pipeline_registers_a_pair_and_refuses_a_flat_one(synthetic_root):
  pair = registration_sets.read_registration_set(synthetic_root / 'test_kitti')[0]
  c1, c2 = (io.read_cloud(p) for p in (pair.cloud1, pair.cloud2))
  for settings in ('paper', 'tutorial'):
    t, seconds, stats = reference.open3d_register(c1, c2, settings=settings)
    assert metrics.registration_errors(pair.transform, t)['success']
    assert set(seconds) == {'features', 'matching', 'ransac'} and min(seconds.values()) >= 0
    assert 3 <= stats['inliers'] <= stats['matches'] and 0 < stats['fitness'] <= 1
    # ISS found by the project's detector is Open3D's same call (the evaluation shares it).
    iss = (keypoints.iss(c1), keypoints.iss(c2))
    t, _, shared = reference.open3d_register(c1, c2, settings=settings, iss=iss)
    assert metrics.registration_errors(pair.transform, t)['success']
    assert shared['matches'] == stats['matches'] == len(iss[0])
  with pytest.raises(ValueError, match="settings must be one of"):
    reference.open3d_register(c1, c2, settings='pcl')
  flat = np.c_[np.random.default_rng(0).uniform(-10, 10, (2000, 2)), np.zeros(2000)]
  with pytest.raises(ValueError, match='too few ISS keypoints'):
    reference.open3d_register(flat, flat)


def test_farthest_point_order_is_the_sampling_of_every_prefix():
  """The first j picks of the order are the j-point sampling (the coarse level of the
  register defaults is the 512-point one), and sorted they are the keypoints."""
  pts = np.random.default_rng(0).uniform(-20, 20, (3000, 3))
  order = keypoints.farthest_point_order(pts, 300)
  assert len(np.unique(order)) == 300
  for j in (1, 50, 150, 300):
    np.testing.assert_array_equal(np.sort(order[:j]), keypoints.farthest_point_keypoints(pts, j))
  coarse, idx = (level() for level in cloud_features.auto_levels(pts, coarse=100, num=300))
  np.testing.assert_array_equal(coarse, np.sort(order[:100]))
  np.testing.assert_array_equal(idx, np.sort(order))


def test_fpfh_takes_every_neighbour_within_its_radius_unless_capped():
  """The default (max_nn 0) is the radius search: equal to a cap no neighbourhood
  reaches, and other than a cap some neighbourhoods exceed."""
  pts = np.random.default_rng(0).uniform(-6, 6, (3000, 3)) * [1, 1, 0.3]
  kp = np.arange(0, 3000, 300)
  radius_only = features.fpfh(pts, kp)
  np.testing.assert_allclose(radius_only, features.fpfh(pts, kp, max_nn=3000), atol=1e-4)
  assert np.abs(radius_only - features.fpfh(pts, kp, max_nn=50)).max() > 1.0


def test_farthest_point_keypoints_are_spread_and_deterministic():
  pts = np.random.default_rng(0).uniform(-20, 20, (3000, 3))
  idx = keypoints.farthest_point_keypoints(pts, 200)
  assert len(idx) == 200 and np.array_equal(idx, keypoints.farthest_point_keypoints(pts, 200))
  # Every point lies within the covering radius of the chosen ones, which is far below
  # what 200 random points leave uncovered.
  cover = lambda chosen: spatial.cKDTree(pts[chosen]).query(pts)[0].max()
  assert cover(idx) < 0.7 * cover(np.random.default_rng(1).choice(3000, 200, replace=False))
  assert len(keypoints.farthest_point_keypoints(pts[:5], 200)) == 5
  # Past its budget it samples every 3rd point (a map tile's grid): on 10 times as many
  # points, within 10 % of the covering radius of sampling them all.
  dense = np.random.default_rng(0).uniform(-20, 20, (30000, 3))
  strided = keypoints.farthest_point_keypoints(dense, 200, max_points=10000)
  assert len(strided) == 200 and np.all(strided % 3 == 0)
  cover = lambda chosen: spatial.cKDTree(dense[chosen]).query(dense)[0].max()
  assert cover(strided) < 1.1 * cover(keypoints.farthest_point_keypoints(dense, 200))


def _sparse_rings(seed=0, rings=6):
  """A 16-beam-like cloud: a few rings on the ground and a wall, ~40 points each."""
  rng = np.random.default_rng(seed)
  pts = []
  for r in np.linspace(4, 30, rings):
    a = rng.uniform(-np.pi, np.pi, 40)
    pts.append(np.c_[r * np.cos(a), r * np.sin(a), np.full(40, -1.7)])
  wall = np.c_[rng.uniform(-10, 10, 60), np.full(60, 12.0), rng.uniform(-1.7, 3, 60)]
  return np.concatenate(pts + [wall])


@pytest.mark.real_data
def test_iss_falls_back_on_a_sparse_cloud_and_says_so():
  dense = io.read_cloud(shared_path('example', 'kitti_00_001554.bin'))
  idx, note = keypoints.iss_with_fallbacks(dense)
  assert note == '' and np.array_equal(idx, keypoints.iss(dense))
  sparse = _sparse_rings()
  assert len(keypoints.iss(sparse)) < keypoints.ENOUGH_KEYPOINTS
  idx, note = keypoints.iss_with_fallbacks(sparse)
  assert len(idx) >= 3 and f'ISS found {len(keypoints.iss(sparse))} keypoints in {len(sparse)}' \
      in note and ('farthest-point' in note or 'radii' in note), note
  # The pipeline carries the note, and a sparse pair registers instead of failing.
  reg, f1, _ = pipeline.register(target=sparse, source=sparse, options=options_lib.Options.paper())
  assert f1.note == note and any(note in n for n in reg.notes)
  # The evaluation protocol keeps the paper's ISS: too few keypoints fail the pair there.
  idx, note = cloud_features.compute_keypoints(sparse, 'iss', fallback=False)
  assert note == '' and len(idx) == len(keypoints.iss(sparse))
  auto, _ = cloud_features.compute_keypoints(sparse, 'auto')
  np.testing.assert_array_equal(auto, keypoints.farthest_point_keypoints(sparse, 1024))


def test_upright_fit_is_exact_and_upright_ransac_finds_a_pose_at_few_inliers():
  rng = np.random.default_rng(0)
  src = rng.uniform(-30, 30, (400, 3))
  t_true = geometry.make_transform(geometry.rotation_z(np.radians(130.0)), np.array([5.0, -3, 0.4]))
  dst = src @ t_true[:3, :3].T + t_true[:3, 3]
  np.testing.assert_allclose(ransac.upright_fit(src[:2], dst[:2]), t_true, atol=1e-9)
  # 4 % correct correspondences, the scan tilted by 2 degrees: 3-point samples would need
  # ~72,000 trials; 2-point ones find it, and the 6-DoF refit takes up the tilt.
  tilt = np.radians(2.0)
  rx = np.array([[1, 0, 0], [0, np.cos(tilt), -np.sin(tilt)], [0, np.sin(tilt), np.cos(tilt)]])
  t_tilt = t_true.copy()
  t_tilt[:3, :3] = t_true[:3, :3] @ rx
  dst = src @ t_tilt[:3, :3].T + t_tilt[:3, 3] + rng.normal(0, 0.05, src.shape)
  wrong = rng.random(400) > 0.04
  dst[wrong] = rng.uniform(-30, 30, (wrong.sum(), 3))
  samples = ransac.draw_upright_samples(np.random.default_rng(1), src, 10_001)
  res = ransac.ransac_upright(dst, src, samples)
  err = metrics.registration_errors(t_tilt, res.transform)
  assert err['rte'] < 0.2 and err['rre_geodesic'] < 0.5 and res.inliers[~wrong].mean() > 0.9
  reg = pair_stages.estimate(cloud_features.CloudFeatures(dst, np.eye(400), {}),
                             cloud_features.CloudFeatures(src, np.eye(400), {}),
                             estimator='upright')
  assert metrics.registration_errors(t_tilt, reg.transform)['success']
  assert 0 < reg.fitness <= 1 and reg.correspondence_set_size == round(reg.fitness * 400)
  assert 0 < reg.inlier_rmse < 1.0
  with pytest.raises(ValueError, match='estimator must be one of'):
    pair_stages.estimate(cloud_features.CloudFeatures(dst, np.eye(400), {}),
                         cloud_features.CloudFeatures(src, np.eye(400), {}), estimator='affine')


@pytest.mark.real_data
@pytest.mark.slow
def test_fpfh_keeps_its_4m_ball_on_a_dense_cloud_and_is_unchanged_on_a_voxelised_one():
  voxelised = io.read_cloud(shared_path('example', 'kitti_00_001554.bin'))
  kp = keypoints.iss(voxelised)[:50]
  np.testing.assert_array_equal(features.fpfh(voxelised, kp),
                                features.fpfh(voxelised, kp, search_voxel=0.0))
  # A dense copy (every point 4 times, 5 cm apart): the neighbour cap would shrink the
  # ball; on the grid its histograms match the voxelised cloud's far better.
  rng = np.random.default_rng(0)
  dense = np.concatenate([voxelised] + [voxelised + rng.normal(0, 0.05, voxelised.shape)
                                        for _ in range(3)]).astype(np.float32)
  ref = features.fpfh(voxelised, kp)
  gridded, capped = features.fpfh(dense, kp), features.fpfh(dense, kp, search_voxel=0.0)
  dist = lambda a: np.linalg.norm(a - ref, axis=1).mean()
  assert dist(gridded) < 0.7 * dist(capped)


@pytest.mark.slow
def test_a_dense_copy_registers_on_the_grid_to_the_same_transform(synthetic_root):
  """A pair densified 12x (3 cm jitter, ~250 k points per cloud) is put on the 0.2 m grid
  and registers to the transform of the pair as given (5 cm, 0.2 degrees); voxel=0
  keeps every point; a cloud already on the grid is used as given."""
  pair = registration_sets.read_registration_set(synthetic_root / 'test_kitti')[0]
  c1, c2 = (io.read_cloud(p).astype(np.float64) for p in (pair.cloud1, pair.cloud2))
  rng = np.random.default_rng(0)
  dense = [np.repeat(c, 12, axis=0) + rng.normal(0, 0.03, (12 * len(c), 3)) for c in (c1, c2)]
  options = options_lib.Options(descriptor='fpfh', verify=0, icp=True)
  reg, f1, f2 = pipeline.register(target=c1, source=c2, options=options)
  assert [n for n in reg.notes if 'used as given' in n] == [
      f'voxel: cloud {n}: {len(c):,} points, no denser than the 0.2 m grid: used as given'
      for n, c in ((1, c1), (2, c2))]
  stages = []
  reg_d, g1, g2 = pipeline.register(target=dense[0], source=dense[1], options=options,
                                    progress=stages.append)
  assert stages == ['cloud 1: grid', 'cloud 1: keypoints', 'cloud 1: descriptors',
                    'cloud 2: grid', 'cloud 2: keypoints', 'cloud 2: descriptors',
                    'RANSAC', 'ICP']
  gridded = reg_d.notes[0].split()
  assert reg_d.notes[0] == (f'voxel: cloud 1: {len(dense[0]):,} -> {gridded[5]} points on '
                            'the 0.2 m grid')
  assert int(gridded[5].replace(",", "")) < 2 * len(c1)   # vs 12x as given
  assert metrics.registration_errors(pair.transform, reg.transform)['success']
  diff = geometry.invert_transform(reg.transform) @ reg_d.transform
  assert np.linalg.norm(diff[:3, 3]) < 0.05
  assert geometry.geodesic_angle_deg(diff[:3, :3], np.eye(3)) < 0.2
  grid, note = cloud_features.to_grid(dense[0], 0.0)
  assert grid is dense[0] and note == ''


@pytest.mark.real_data
def test_verification_picks_the_pose_the_clouds_agree_with_among_ransacs_runners_up():
  """Correspondences of a street that repeats every 12 m: RANSAC's best pose is one period
  off (the decoy matches outnumber the true ones), the true pose is a runner-up; the
  check against the clouds picks it and ICP makes it exact."""
  scan = io.read_cloud(shared_path('kitti_object_velodyne', '000000.bin')).astype(np.float64)
  cloud1 = scan[np.linalg.norm(scan[:, :2], axis=1) < 30]
  t_true = geometry.make_transform(geometry.rotation_z(np.radians(40.0)), np.array([3.0, 1.0, 0.0]))
  cloud2 = (cloud1 - t_true[:3, 3]) @ t_true[:3, :3]      # T_12 maps cloud 2 onto cloud 1
  rng = np.random.default_rng(0)
  idx = rng.choice(len(cloud1), 300, replace=False)
  xyz2 = cloud2[idx]
  xyz1 = cloud1[idx].copy()
  xyz1[:180] += np.array([12.0, 0.0, 0.0])               # the decoy: one period along x
  xyz1[240:] = rng.uniform(-30, 30, (60, 3))             # and plain outliers
  samples = ransac.draw_upright_samples(np.random.default_rng(1), xyz2, 10_001)
  res = ransac.ransac_upright(xyz1, xyz2, samples, candidates=5)
  assert res.candidates.shape[1:] == (4, 4) and 2 <= len(res.candidates) <= 5
  np.testing.assert_array_equal(res.candidates[0], res.transform)
  assert not metrics.registration_errors(t_true, res.transform)['success']   # the decoy
  f1 = cloud_features.CloudFeatures(xyz1, np.eye(300), {})
  f2 = cloud_features.CloudFeatures(xyz2, np.eye(300), {})
  estimated = pair_stages.estimate(f1, f2, estimator='upright', candidates=5)
  assert len(estimated.candidates) <= 5
  np.testing.assert_array_equal(estimated.candidates[0], estimated.transform)
  reg = dataclasses.replace(estimated, transform=res.transform, inliers=res.inliers,
                            candidates=res.candidates)
  verified = pair_stages.verify(reg, f1, f2, cloud1, cloud2)
  err = metrics.registration_errors(t_true, verified.transform)
  assert err['rte'] < 0.05 and err['rre_geodesic'] < 0.2, err
  assert verified.verified_fitness.max() > 0.9 > verified.verified_fitness[0]
  assert verified.inliers.sum() < reg.inliers.sum()    # recounted: the true matches only
  # Hypotheses within 2 m and 5 degrees of a better one are not candidates of their own.
  near = np.stack([res.transform, res.transform @ geometry.make_transform(np.eye(3),
                                                                          np.array([1.0, 0, 0]))])
  assert ransac.distinct_best(near, np.array([5, 4]), 2) == [0]


def _upright_correspondences(rng, n, inliers):
  """n matches of upright scans, the first `inliers` of them correct (5 cm noise)."""
  t_true = geometry.make_transform(geometry.rotation_z(np.radians(-70.0)), np.array([9.0, 4, 0.3]))
  xyz2 = np.concatenate([rng.uniform(-40, 40, (n, 2)), rng.uniform(-2, 4, (n, 1))], 1)
  xyz1 = xyz2 @ t_true[:3, :3].T + t_true[:3, 3] + rng.normal(0, 0.05, (n, 3))
  xyz1[inliers:] = np.concatenate([rng.uniform(-40, 40, (n - inliers, 2)),
                                   rng.uniform(-2, 4, (n - inliers, 1))], 1)
  return t_true, xyz1, xyz2


def test_compatible_pairs_keep_every_pair_of_correct_matches_and_few_others(monkeypatch):
  _, xyz1, xyz2 = _upright_correspondences(np.random.default_rng(0), 1000, 12)
  pairs = ransac.compatible_pairs(xyz1, xyz2, 1.0)
  assert np.all(pairs[:, 0] < pairs[:, 1])
  kept = {tuple(p) for p in pairs.tolist()}
  assert all((i, j) in kept for i in range(12) for j in range(i + 1, 12))
  # A random pair passes when two random distances and two random height shifts agree
  # within 1 m: a few per cent of the 499,500 pairs.
  assert 0.001 < len(pairs) / (1000 * 999 / 2) < 0.05
  monkeypatch.setattr(ransac, 'PAIR_BLOCK', 97)   # blocks that do not divide the matches
  np.testing.assert_array_equal(ransac.compatible_pairs(xyz1, xyz2, 1.0), pairs)


def test_compatible_samples_find_the_pose_where_uniform_draws_run_out():
  """12 correct matches of 1,000 (1.2 %): a uniform 2-point sample is all-inlier once in
  ~7,600 draws, so 10,000 trials find the pose about as often as not and the stopping
  rule is never met; among the compatible pairs one sample in a few hundred is."""
  t_true, xyz1, xyz2 = _upright_correspondences(np.random.default_rng(0), 1000, 12)
  samples, pairs = ransac.draw_compatible_samples(np.random.default_rng(1), xyz1, xyz2,
                                                  10_001, 1.0)
  assert len(samples) == min(pairs, 10_001) and len(np.unique(samples, axis=0)) == len(samples)
  guided = ransac.ransac_upright(xyz1, xyz2, samples, pairs=pairs)
  err = metrics.registration_errors(t_true, guided.transform)
  assert err['rte'] < 0.1 and err['rre_geodesic'] < 0.2, err
  assert guided.inliers[:12].all() and guided.trials < 2000
  uniform = ransac.ransac_upright(
      xyz1, xyz2, ransac.draw_upright_samples(np.random.default_rng(1), xyz2, 10_001))
  assert uniform.trials == 10_001
  # No compatible pair (matches 9 m apart in cloud 1, 5 m in cloud 2): the uniform
  # draws, so RANSAC still has samples.
  samples, pairs = ransac.draw_compatible_samples(
      np.random.default_rng(1), np.array([[0.0, 0, 0], [9.0, 0, 0]]),
      np.array([[0.0, 0, 0], [5.0, 0, 0]]), 11, 1.0)
  assert pairs == 0 and samples.shape == (11, 2)


def test_matches_both_ways_add_the_sparser_clouds_nearest_neighbours():
  desc1 = np.array([[0.0], [1.0], [2.0], [10.0]])
  desc2 = np.array([[0.1], [9.0], [9.5]])
  # Cloud 1 -> 2: 0->0, 1->0, 2->0, 10->2; cloud 2 -> 1: 0.1->0, 9->3, 9.5->3.
  np.testing.assert_array_equal(matching.both_ways_matches(desc1, desc2),
                                [[0, 0], [1, 0], [2, 0], [3, 1], [3, 2]])
  t_true, xyz1, xyz2 = _upright_correspondences(np.random.default_rng(2), 300, 30)
  f1 = cloud_features.CloudFeatures(xyz1, np.eye(300), {})
  f2 = cloud_features.CloudFeatures(xyz2, np.eye(300), {})
  for sampling in options_lib.SAMPLINGS:
    reg = pair_stages.estimate(f1, f2, estimator='upright', sampling=sampling)
    np.testing.assert_array_equal(reg.matches, np.stack([np.arange(300)] * 2, 1))
    assert metrics.registration_errors(t_true, reg.transform)['success'], sampling
  with pytest.raises(ValueError, match='sampling must be one of'):
    pair_stages.estimate(f1, f2, estimator='upright', sampling='guided')
  with pytest.raises(Exception, match='sampling must be one of'):
    options_lib.Options(sampling='guided')
