"""Free-space consistency and the verdict on a pose (`registered` with its reason)."""

import dataclasses

import numpy as np
import pytest

from ssd_jax import geometry, inference, pretrained
from ssd_jax.data import clean, groundtruth, io, kitti
from ssd_jax.infra import errors
from ssd_jax.registration import bev, cloud_features, free_space, metrics, outputs, pipeline
from ssd_jax.registration import icp, keypoints, pair_stages, prepared
from ssd_jax.registration import uncertainty, verdict, verification
from ssd_jax.registration import options as options_lib
from tests.conftest import shared_path


def _drive_pair(i, j):
  folder = shared_path('real_drives', 'kaist03')
  poses = kitti.read_poses(folder / 'poses.txt')
  read = lambda n: clean.clean_cloud(io.read_cloud(folder / 'scans' / f'{n:06d}.bin'), '',
                                     np.float64)
  return read(i), read(j), groundtruth.relative_pose(poses, i, j)


@pytest.mark.real_data
def test_a_pose_shifted_along_the_street_puts_structure_in_the_other_scans_free_space():
  """Two real scans 7.8 m apart: under the drive's pose few of either's structure points
  lie where the other's rays passed; shifted back to the same spot (the wrong pose a
  repeated street gives), many do."""
  cloud1, cloud2, t12 = _drive_pair(0, 7)
  pair = prepared.PreparedPair(cloud1, cloud2)
  assert pair.cloud1.range_image is not None and pair.cloud2.range_image is not None
  right = pair.conflict(t12)
  shifted = t12.copy()
  shifted[:3, 3] = 0.0
  wrong = pair.conflict(shifted)
  assert right < 0.03 and wrong > 1.5 * verdict.MAX_CONFLICT, (right, wrong)
  # Cached per pose, and the same from a fresh pair (deterministic).
  assert pair.conflict(shifted) == wrong == prepared.PreparedPair(cloud1, cloud2).conflict(shifted)
  # The verification's pick among the two: the right one, though it fits less.
  assert free_space.ranked(np.array([0.5, 0.45]), lambda c: (wrong, right)[c])[0] == 1
  assert free_space.ranked(np.array([0.5, 0.45]), lambda c: None)[0] == 0


@pytest.mark.real_data
def test_only_scans_in_their_sensors_frames_are_judged():
  cloud1, _, _ = _drive_pair(0, 7)
  assert free_space.sensor_centred(cloud1)
  # Map coordinates: the origin kilometres away.
  assert not free_space.sensor_centred(cloud1 + [4.5e5, 5.4e6, 30.0])
  # A map tile or submap centred on its points: its ground runs under the origin.
  ground = np.stack(np.meshgrid(np.arange(-5, 5, 0.1), np.arange(-5, 5, 0.1)), -1).reshape(-1, 2)
  tile = np.concatenate([cloud1, np.c_[ground, np.full(len(ground), -1.8)]])
  assert not free_space.sensor_centred(tile)
  # A forward-looking unit pitched down sees the ground just ahead of it, in its view: as
  # many points near its axis as the tile has, on one side.
  near_tile = int(np.sum(np.linalg.norm(tile[:, :2], axis=1) < free_space.BLIND_RADIUS))
  rng = np.random.default_rng(0)
  x = rng.uniform(0.2, 1.0, near_tile)
  ahead = np.c_[x, x * rng.uniform(-0.6, 0.6, near_tile), np.full(near_tile, -1.2)]
  assert free_space.sensor_centred(np.concatenate([cloud1, ahead]))
  # A real one: a hand-held Livox Avia scan pitched down, 8 % of its points within 1 m of
  # its axis.
  livox = clean.clean_cloud(io.read_cloud(
      shared_path('real_drives', 'livox_quick_shack', 'scans', '000010.bin')), '', np.float64)
  assert np.mean(np.linalg.norm(livox[:, :2], axis=1) < 1.0) > 0.05
  assert free_space.sensor_centred(livox)
  assert prepared.PreparedPair(tile, cloud1).conflict(np.eye(4)) is None


def test_a_range_image_keeps_the_nearest_return_per_direction():
  wall = np.stack([np.full(200, 10.0), np.linspace(-2, 2, 200), np.linspace(-1, 1, 200)], 1)
  behind = wall * 2.0       # the same directions, twice as far
  image = free_space.range_image(np.concatenate([wall, behind]))
  e, a, r = image.cells(wall)
  np.testing.assert_allclose(image.nearest[e, a], r, rtol=0.02)
  # A point 5 m in front of the wall conflicts; one behind it or 0.5 m before it does not;
  # one nearer the sensor than MIN_JUDGED_RANGE or beyond its farthest return is not judged.
  probe = np.array([[5.0, 0.0, 0.0], [15.0, 0.0, 0.0], [9.5, 0.0, 0.0], [2.0, 0.0, 0.0],
                    [30.0, 0.0, 0.0]])
  assert free_space.conflicts(image, probe) == (1, 3)


def test_the_verification_takes_first_the_best_pose_the_verdict_would_not_refuse_for_its_sides():
  """Candidates ranked by fitness less twice the conflict; one the verdict refuses as seen
  from behind (over MAX_BEHIND where it fits under CONFIDENT_FITNESS) yields to the next,
  which is asked only as far as needed; where every one is refused the order stands."""
  fitness = np.array([0.39, 0.27, 0.30, 0.6])
  conflict = [0.10, 0.08, 0.30, 0.0]
  behind = [0.97, 0.01, 0.02, 0.9]
  assert list(free_space.ranked(fitness, conflict.__getitem__)) == [3, 0, 1, 2]
  asked = []
  refused = lambda c: asked.append(c) or verdict.seen_from_behind(fitness[c], behind[c])
  # 3 fits 0.6: confident, its sides not held against it.
  assert list(free_space.ranked(fitness, conflict.__getitem__, refused)) == [3, 0, 1, 2]
  assert asked == [3]
  asked.clear()
  assert list(free_space.ranked(fitness[:3], conflict.__getitem__, refused)) == [1, 0, 2]
  assert asked == [0, 1]
  assert list(free_space.ranked(fitness[:3], conflict.__getitem__, lambda c: True)) == [0, 1, 2]
  assert not verdict.seen_from_behind(0.39, None)


def _wall_seen_from(x: float, n: int = 400) -> np.ndarray:
  """A wall in the plane x = 0 (y, z within 4 m), in the frame of a sensor at x = -x."""
  rng = np.random.default_rng(0)
  return np.c_[np.full(n, x), rng.uniform(-4, 4, n), rng.uniform(-2, 2, n)]


def test_a_surface_both_sensors_see_from_opposite_sides_is_seen_from_behind():
  """One wall, scanned by two sensors 5 m from it: both on one side, none of it is seen
  from behind; laid on each other with the sensors on the two sides (the second turned to
  face the wall from its back), all of it is; too few points to judge, 0."""
  wall1, wall2 = _wall_seen_from(5.0), _wall_seen_from(5.0)
  surface = lambda p: prepared.PreparedCloud(p).target
  measure = lambda t, a=wall1, b=wall2: free_space.seen_from_behind(
      surface(a), surface(b), a, b, t, 0.3)
  assert measure(np.eye(4)) == 0.0
  back = geometry.make_transform(geometry.rotation_z(np.pi), np.array([10.0, 0.0, 0.0]))
  assert measure(back) == 1.0
  few = _wall_seen_from(5.0, free_space.MIN_FACING_POINTS - 1)
  assert measure(back, few, few) == 0.0


def test_a_cloud_sparser_than_the_verdicts_calibration_is_told_so():
  """The verdict was calibrated on clouds whose points lie 0.1-0.3 m apart: a cloud whose
  points lie 0.7 m apart is used as given, with a note that the verdict may refuse right
  poses; one 0.25 m apart is used as given without it."""
  def lattice(step):
    axis = np.arange(12) * step
    return np.stack(np.meshgrid(axis, axis, axis), -1).reshape(-1, 3)
  assert keypoints.point_spacing(lattice(0.7)) == pytest.approx(0.7)
  _, sparse = cloud_features.to_grid(lattice(0.7), 0.2)
  assert sparse.startswith('1,728 points, no denser than the 0.2 m grid: used as given')
  assert '0.7 m apart (median)' in sparse and 'may refuse right poses' in sparse
  _, dense = cloud_features.to_grid(lattice(0.25), 0.2)
  assert dense == '1,728 points, no denser than the 0.2 m grid: used as given'


def test_each_reason_of_the_verdict():
  ok = verdict.judge(0.6, 0.02)
  assert ok.registered and ok.reason == '' and ok.line() == 'registered'
  cases = {'degenerate': dict(fitness=0.9, conflict=0.0, free='translation along x'),
           'free-space conflict': dict(fitness=0.9, conflict=0.3),
           'seen from behind': dict(fitness=0.3, conflict=0.0, behind=0.8),
           'low overlap': dict(fitness=0.1, conflict=0.0),
           'ambiguous candidates': dict(fitness=0.4, conflict=0.0, runner_up=0.38),
           'unsupported': dict(fitness=0.2, conflict=0.0, support=1)}
  for kind, kwargs in cases.items():
    v = verdict.judge(**kwargs)
    assert not v.registered and v.kind == kind and v.reason.startswith(kind + ': '), v
    assert v.line() == f'NOT registered ({v.reason})'
  # Not judged for free space (None): the other reasons alone.
  assert verdict.judge(0.6, None).registered
  assert verdict.judge(0.6, 0.02, runner_up=0.5).registered   # a runner-up clearly behind
  # One RANSAC sample's matches support a pose; so does a fit the geometry alone vouches for.
  assert verdict.judge(0.2, 0.0, support=verdict.MIN_SUPPORT).registered
  assert verdict.judge(verdict.SUPPORTED_FITNESS, 0.0, support=0).registered
  # A pose that fits as well as a re-scan's right ones is not refused for its sides.
  assert verdict.judge(verification.CONFIDENT_FITNESS, 0.0, behind=0.99).registered
  assert verdict.judge(0.3, 0.0, behind=verdict.MAX_BEHIND).registered
  assert set(verdict.REASONS) == set(cases)
  assert verdict.judge(0.6, 0.02).to_json() == {
      'registered': True, 'reason': '', 'fitness': 0.6, 'free_space_conflict': 0.02,
      'runner_up_fitness': None, 'support': None, 'seen_from_behind': None}


@pytest.mark.real_data
def test_the_verdict_on_a_right_and_a_wrong_pose_of_real_scans():
  cloud1, cloud2, t12 = _drive_pair(0, 7)
  pair = prepared.PreparedPair(cloud1, cloud2)
  right = verdict.assess(pair, t12)
  assert right.registered and right.behind < 0.05, right
  wrong = t12.copy()
  wrong[:3, 3] += [6.0, 0.0, 0.0]
  judged = verdict.assess(pair, wrong)
  assert not judged.registered and judged.kind in ('free-space conflict', 'low overlap'), judged
  # Without the free-space check (clouds off their sensors' frames) the other reasons hold.
  no_viewpoint = prepared.PreparedPair(prepared.PreparedCloud(cloud1, viewpoint=False), cloud2)
  assert verdict.assess(no_viewpoint, t12).conflict is None
  # A distinct candidate said to fit as well (3 m up; free space not judged, else it lies
  # in scan 1's empty space) makes the right pose ambiguous; said to fit clearly less, not.
  twin = t12.copy()
  twin[:3, 3] += [0.0, 0.0, 3.0]
  for said, ambiguous in ((right.fitness, True), (right.fitness - 0.1, False)):
    judged = verdict.assess(no_viewpoint, t12, candidates=np.stack([t12, twin]),
                            candidate_fitness=np.array([right.fitness, said]))
    assert (judged.kind == 'ambiguous candidates') == ambiguous, (said, judged)


def test_a_pose_is_ambiguous_beside_a_distinct_candidate_that_fits_as_well():
  """A row of 41 posts 5 m apart seen twice: the pose one post along fits within
  AMBIGUOUS_MARGIN of the right one, two and a half posts along it does not."""
  rng = np.random.default_rng(0)
  posts = np.concatenate([np.c_[rng.uniform(-0.25, 0.25, (300, 2)) + [x, 0.0],
                                rng.uniform(0.0, 3.0, 300)] for x in np.arange(-100, 101, 5)])
  pair = prepared.PreparedPair(prepared.PreparedCloud(posts, viewpoint=False),
                               prepared.PreparedCloud(posts + rng.normal(0, 0.02, posts.shape),
                                                      viewpoint=False))
  fit = lambda t: verification.fitness(pair.cloud1.target, pair.cloud2.source.scored, t)
  for x, ambiguous in ((5.0, True), (12.5, False)):
    candidates = np.stack([np.eye(4), geometry.make_transform(np.eye(3), np.array([x, 0, 0]))])
    judged = verdict.assess(pair, np.eye(4), candidates=candidates,
                            candidate_fitness=np.array([fit(t) for t in candidates]))
    assert (judged.kind == 'ambiguous candidates') == ambiguous, (x, judged)
  assert judged.registered and judged.fitness > 0.95



@pytest.mark.real_data
def test_register_returns_the_verdict_with_the_pose():
  """The Python API: `pipeline.register` gives the verdict with the pose (FPFH, the
  defaults otherwise), registered for two real scans 7.8 m apart."""
  cloud1, cloud2, t12 = _drive_pair(0, 7)
  reg, _, _ = pipeline.register(target=cloud1, source=cloud2,
                                options=options_lib.Options(descriptor='fpfh'))
  assert metrics.registration_errors(t12, reg.transform)['success']
  assert reg.verdict.registered and reg.verdict.conflict is not None, reg.verdict
  assert reg.verdict.fitness >= verdict.MIN_FITNESS
  assert reg.verdict.support == int(reg.inliers.sum()) >= verdict.MIN_SUPPORT   # judged on


@pytest.mark.real_data
def test_scans_in_one_frame_are_registered_without_free_space():
  """Scan 2 given in scan 1's frame (its sensor 7.8 m from the origin, as odometry or a
  map puts it) still looks like a scan in its sensor's frame; judged from the origin, the
  right pose (now the identity) puts several times more structure in the other scan's
  'free space' than the same pose between the sensors' frames. `free_space=False` judges
  neither free space nor sides: the right pose is trusted."""
  cloud1, cloud2, t12 = _drive_pair(0, 7)
  moved = np.asarray(geometry.apply_transform(t12, cloud2))
  assert free_space.sensor_centred(moved)
  own_frames = prepared.PreparedPair(cloud1, cloud2).conflict(t12)
  assert prepared.PreparedPair(cloud1, moved).conflict(np.eye(4)) > 3 * own_frames
  no_viewpoint = prepared.PreparedCloud(moved, viewpoint=False)
  assert prepared.PreparedPair(cloud1, no_viewpoint).conflict(np.eye(4)) is None
  reg, _, _ = pipeline.register(target=cloud1, source=moved,
                                options=options_lib.Options(descriptor='fpfh', free_space=False))
  assert metrics.registration_errors(np.eye(4), reg.transform)['success']
  assert reg.verdict.registered, reg.verdict
  assert reg.verdict.conflict is None and reg.verdict.behind is None


@pytest.mark.real_data
def test_a_refused_pose_is_registered_again_with_fpfh(monkeypatch):
  """A learned descriptor that fails on a pair (here noise at any sampling: its candidates
  hold no right pose, and the BEV search is off) leaves a pose the verdict refuses; the
  retry registers the pair again, with keypoints on the structure and with the model's
  own sampling (noise again, refused) and then with FPFH at farthest-point keypoints, and
  keeps FPFH's pose, which is right and trusted, with a note saying so. Without the retry
  the refused pose stands."""
  cloud1, cloud2, t12 = _drive_pair(0, 7)
  monkeypatch.setattr(inference, 'describe', lambda model, points, at, **kw: (
      np.random.default_rng(len(points)).normal(size=(len(at), 32)).astype(np.float32)))
  model = pretrained.load(pretrained.DEFAULT)
  registered = {}
  for retry in ('none', 'fpfh', options_lib.Options().retry):
    registered[retry], f1, _ = pipeline.register(
        target=cloud1, source=cloud2, model=model,
        options=options_lib.Options(bev=0, retry=retry))
  first, again, both = registered['none'], registered['fpfh'], registered[options_lib.RETRIES]
  assert not first.verdict.registered, first.verdict
  assert not metrics.registration_errors(t12, first.transform)['success']
  assert again.verdict.registered, again.verdict
  assert metrics.registration_errors(t12, again.transform)['success']
  assert f1.descriptors.shape[1] == 33   # FPFH's 33 bins: the features of the pose kept
  note = pipeline.RETRY_NOTES['fpfh'].format(first.verdict.reason)
  assert note in again.notes and note in both.notes, (again.notes, both.notes)
  np.testing.assert_array_equal(both.transform, again.transform)
  row = outputs.csv_row(pipeline.PairResult('a.bin', 'b.bin', again, f1, f1))   # a batch's
  assert note in row[outputs.CSV_HEADER.index('notes')]
  assert again.seconds['ransac'] > first.seconds['ransac']   # both tries are counted
  # A retry's pose must hold every shift by verdict.RETRY_MIN_CONSTRAINT, 4x a first try's
  # bound: asked for more than FPFH's pose holds, the retry is refused too, and the first
  # refusal (the scans barely overlap there: nothing contradicts it) stands.
  held = again.uncertainty.translation_constraint[0]
  assert held >= verdict.RETRY_MIN_CONSTRAINT > uncertainty.MIN_CONSTRAINT
  monkeypatch.setattr(verdict, 'RETRY_MIN_CONSTRAINT', 1.01 * held)
  strict, _, _ = pipeline.register(target=cloud1, source=cloud2, model=model,
                                   options=options_lib.Options(bev=0, retry='fpfh'))
  assert not strict.verdict.registered and strict.verdict.reason == first.verdict.reason
  assert first.verdict.kind not in pipeline.CONTRADICTED
  np.testing.assert_array_equal(strict.transform, first.transform)


def test_where_every_pose_is_refused_the_first_stands_unless_the_scans_contradict_it():
  """Every try refused: a first pose refused as ambiguous or for low overlap stands (it
  may be right); one the scans contradict (free space, sides) yields to the retries' pose
  that ranks first as the verification ranks them, those not contradicted first."""
  conflicted = verdict.judge(0.31, 0.23)                    # HKU_MB 216-283's first pose
  twin = verdict.judge(0.19, 0.02, runner_up=0.17)          # its bev retry's, right
  behind = verdict.judge(0.39, 0.05, behind=0.97)
  low = verdict.judge(0.12, 0.0)
  assert conflicted.kind == 'free-space conflict' and twin.kind == 'ambiguous candidates'
  assert pipeline.kept_of_refused([conflicted, behind, twin, low]) == 2
  assert pipeline.kept_of_refused([twin, conflicted, low]) == 0
  assert pipeline.kept_of_refused([low, twin]) == 0
  assert pipeline.kept_of_refused([conflicted, behind]) == 1   # both contradicted: by score



@pytest.mark.real_data
def test_a_refused_pose_is_registered_again_with_keypoints_on_the_structure(monkeypatch):
  """Where the descriptors at keypoints drawn from every point fail on a pair (here noise
  in their place), the retry draws the keypoints from the structure above the ground
  (`cloud_features.keypoint_domain`) and keeps that pose, right and trusted, before the
  model's own sampling and FPFH are tried."""
  cloud1, cloud2, t12 = _drive_pair(0, 7)
  describe = inference.describe
  monkeypatch.setattr(inference, 'describe', lambda model, points, at, **kw: (
      np.random.default_rng(len(points)).normal(size=(len(at), 32)).astype(np.float32)
      if model.keypoints == 'all' else describe(model, points, at, **kw)))
  reg, f1, _ = pipeline.register(target=cloud1, source=cloud2,
                                 model=pretrained.load(pretrained.DEFAULT),
                                 options=options_lib.Options(bev=0))
  assert reg.verdict.registered and metrics.registration_errors(t12, reg.transform)['success']
  kept = [name for name, note in pipeline.RETRY_NOTES.items()
          if any(n.startswith(note.split('{')[0]) for n in reg.notes)]
  assert kept == ['structure'], reg.notes
  assert f1.descriptors.shape[1] == 32   # the learned descriptors' pose is kept


@pytest.mark.real_data
def test_a_refused_pose_is_registered_again_with_the_banded_bev_search(monkeypatch):
  """Where the descriptors fail (noise in their place) and the structure images' BEV
  search offers only poses 15 m off, the first pose is refused; the 'bev' retry verifies
  the banded search's 5 ranked poses beside every candidate of the first try and keeps a
  right one, trusted."""
  cloud1, cloud2, t12 = _drive_pair(0, 7)
  monkeypatch.setattr(inference, 'describe', lambda model, points, at, **kw: (
      np.random.default_rng(len(points)).normal(size=(len(at), 32)).astype(np.float32)))
  search = bev.search
  off = geometry.make_transform(np.eye(3), np.array([15.0, 0.0, 0.0]))
  monkeypatch.setattr(bev, 'search', lambda *a, banded=False, **kw: (
      search(*a, banded=True, **kw) if banded else bev.BevResult(
          np.stack([t12 @ off] * 2), np.ones(2))))
  run = lambda retry: pipeline.register(target=cloud1, source=cloud2,
                                        model=pretrained.load(pretrained.DEFAULT),
                                        options=options_lib.Options(retry=retry))[0]
  first, again = run('none'), run('bev')
  assert not first.verdict.registered
  assert not metrics.registration_errors(t12, first.transform)['success']
  assert again.verdict.registered and metrics.registration_errors(t12, again.transform)['success']
  assert pipeline.RETRY_NOTES['bev'].format(first.verdict.reason) in again.notes
  assert len(again.verified_fitness) == len(first.verified_fitness) + 5


@pytest.mark.real_data
def test_a_refused_pose_is_registered_again_with_the_models_own_sampling(monkeypatch):
  """Where the first try's sampling of each ball (one of 32 points) fails on a pair (here
  noise in its place), the retry describes the clouds as the model was trained (its own
  draws of 64 points) and keeps that pose, right and trusted, before FPFH is tried."""
  cloud1, cloud2, t12 = _drive_pair(0, 7)
  describe = inference.describe
  monkeypatch.setattr(inference, 'describe', lambda model, points, at, **kw: (
      np.random.default_rng(len(points)).normal(size=(len(at), 32)).astype(np.float32)
      if model.draws == options_lib.VERIFIED_DRAWS else describe(model, points, at, **kw)))
  model = pretrained.load(pretrained.DEFAULT)
  assert model.draws != options_lib.VERIFIED_DRAWS
  reg, _, _ = pipeline.register(target=cloud1, source=cloud2, model=model,
                                options=options_lib.Options(bev=0))
  assert reg.verdict.registered and metrics.registration_errors(t12, reg.transform)['success']
  assert any(n.startswith(pipeline.RETRY_NOTES['learned'].split('{')[0]) for n in reg.notes)
  assert not any('FPFH' in n for n in reg.notes), reg.notes
  # Only the tries that differ from the first are made: no learned one where it already
  # samples each ball as the model was trained, from the structure.
  retries = lambda m, **kw: list(pipeline.Registrar(  # pylint: disable=protected-access
      lambda key: cloud1, model=m, options=options_lib.Options(**kw))._retries)
  assert retries(model) == ['structure', 'learned', 'fpfh', 'bev', 'robust']
  assert retries(model, draws=0) == ['structure', 'fpfh', 'bev', 'robust']
  assert retries(dataclasses.replace(model, keypoints='structure'), draws=0) == [
      'fpfh', 'bev', 'robust']
  assert retries(model, keypoints='iss') == ['learned', 'fpfh', 'bev', 'robust']
  assert retries(model, bev=0) == ['structure', 'learned', 'fpfh']   # no BEV search
  with pytest.raises(errors.UserError, match='retry'):
    options_lib.Options(retry='learned,sift')


@pytest.mark.real_data
def test_a_refused_pose_is_registered_again_by_the_robust_icp(monkeypatch):
  """Where the plain ICP drags every candidate off (here 3 m along the street, as the points
  two far scans do not share drag a right pose), every earlier try is refused; the 'robust'
  retry aligns the 'bev' try's candidates by the robust ICP and keeps the right pose,
  trusted, with its note."""
  cloud1, cloud2, t12 = _drive_pair(0, 7)
  align = icp.point_to_plane
  off = geometry.make_transform(np.eye(3), np.array([3.0, 0.0, 0.0]))

  def dragged(*args, robust=False, **kwargs):
    t, fitness = align(*args, robust=robust, **kwargs)
    return (t if robust else off @ t), fitness

  monkeypatch.setattr(icp, 'point_to_plane', dragged)
  run = lambda retry: pipeline.register(target=cloud1, source=cloud2,
                                        model=pretrained.load(pretrained.DEFAULT),
                                        options=options_lib.Options(retry=retry))[0]
  first, bev, again = run('none'), run('bev'), run('bev,robust')
  for refused in (first, bev):
    assert not refused.verdict.registered
    assert not metrics.registration_errors(t12, refused.transform)['success']
  assert again.verdict.registered and metrics.registration_errors(t12, again.transform)['success']
  assert pipeline.RETRY_NOTES['robust'].format(first.verdict.reason) in again.notes


@pytest.mark.real_data
def test_a_trusted_pose_is_polished_by_the_robust_icp_only_where_still_trusted():
  """A right pose moved 0.4 m and 1.5 degrees off (as the plain ICP drags a far pair's) is
  brought back within 5 cm of the registered pose by `polish`, trusted; a pose 15 m off is
  left as it is."""
  cloud1, cloud2, _ = _drive_pair(0, 7)
  reg, _, _ = pipeline.register(target=cloud1, source=cloud2,
                                model=pretrained.load(pretrained.DEFAULT))
  assert reg.verdict.registered
  nudge = geometry.make_transform(geometry.rotation_z(np.radians(1.5)), np.array([0.4, 0, 0]))
  off = dataclasses.replace(reg, transform=reg.transform @ nudge)
  polished = pair_stages.polish(off, cloud1, cloud2)
  assert polished.verdict.registered
  error = lambda t: metrics.registration_errors(reg.transform, t)
  assert error(off.transform)['rte'] > 0.3
  assert error(polished.transform)['rte'] < 0.05 and error(polished.transform)['rre'] < 0.2
  far = dataclasses.replace(reg, transform=geometry.make_transform(
      np.eye(3), np.array([15.0, 0, 0])) @ reg.transform)
  kept = pair_stages.polish(far, cloud1, cloud2)
  np.testing.assert_array_equal(kept.transform, far.transform)
  assert kept.seconds['icp'] > 0
