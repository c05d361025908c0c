"""Many pairs in one process (`pipeline.register_many`, `pipeline.Registrar`): each cloud
computed once, the same poses as one pair at a time; the verification's and the coarse
level's economies."""

import numpy as np
import pytest

from ssd_jax import geometry, pretrained
from ssd_jax.data import io
from ssd_jax.infra import errors
from ssd_jax.registration import icp, metrics, pipeline, verification
from ssd_jax.registration import cloud_features, pair_stages
from ssd_jax.registration import options as options_lib
from tests.conftest import shared_path


def _views(tmp_path):
  """A real scan (cloud a) and two views of it turned and moved, written as .npy files
  -> ({name: path}, {name: T_a,name})."""
  scan = io.read_cloud(shared_path('kitti_object_velodyne', '000000.bin')).astype(np.float64)
  scan = scan[np.linalg.norm(scan[:, :2], axis=1) < 40]
  paths, truth = {'a': str(tmp_path / 'a.npy')}, {'a': np.eye(4)}
  np.save(paths['a'], scan[::2])
  for n, (yaw, shift) in enumerate(((40.0, [3.0, -2.0, 0.1]), (-120.0, [-4.0, 1.0, 0.0]))):
    t = geometry.make_transform(geometry.rotation_z(np.radians(yaw)), np.array(shift))
    name = 'bc'[n]
    paths[name], truth[name] = str(tmp_path / f'{name}.npy'), t
    np.save(paths[name], (scan[1::2] - t[:3, 3]) @ t[:3, :3])
  return paths, truth


@pytest.mark.real_data
@pytest.mark.slow
def test_register_many_reads_and_prepares_each_cloud_once_and_registers_as_one_pair(tmp_path):
  paths, truth = _views(tmp_path)
  reads = []

  def read(path):
    reads.append(path)
    if path.endswith('missing.npy'):
      raise FileNotFoundError(f'{path}: no such file')
    return np.load(path)

  model = pretrained.load('ours')
  pairs = [('a', 'b'), ('a', 'c'), ('a', 'missing'), ('b', 'c')]
  paths['missing'] = str(tmp_path / 'missing.npy')
  results = {(r.target, r.source): r for r in pipeline.register_many(
      [(paths[a], paths[b]) for a, b in pairs], read, model=model, say=lambda line: None)}
  by_name = {pair: results[paths[pair[0]], paths[pair[1]]] for pair in pairs}
  assert sorted(set(reads)) == sorted(paths.values())       # each cloud read once
  assert len(reads) == len(paths)
  assert 'no such file' in by_name['a', 'missing'].error    # that pair only
  assert by_name['a', 'missing'].registration is None
  seconds = by_name['a', 'b'].registration.seconds
  assert set(seconds) == set(pipeline.STAGES)   # 'icp': the trusted pose's polish
  assert 'read' not in by_name['b', 'c'].registration.seconds   # both met before
  for (one, two), result in by_name.items():
    if two == 'missing':
      continue
    t_true = np.linalg.inv(truth[one]) @ truth[two]
    err = metrics.registration_errors(t_true, result.registration.transform)
    assert err['rte'] < 0.1 and err['rre_geodesic'] < 0.3, (one, two, err)
  alone, _, _ = pipeline.register(target=np.load(paths['a']), source=np.load(paths['c']),
                                  model=model)
  np.testing.assert_allclose(by_name['a', 'c'].registration.transform, alone.transform,
                             atol=1e-6)


def test_options_are_checked_and_say_where_the_bev_search_applies():
  assert options_lib.Options().bev_candidates == 5
  assert options_lib.Options(estimator='rigid').bev_candidates == 0
  assert options_lib.Options(verify=0).bev_candidates == 0
  assert options_lib.Options.paper().keypoints == 'iss'
  for bad, message in (({'verify': -1}, r'verify must be >= 0 \(0: no verification\)'),
                       ({'descriptor': 'shot'}, "descriptor must be one of"),
                       ({'voxel': -0.2}, 'voxel must be >= 0')):
    with pytest.raises(errors.UserError, match=message):
      options_lib.Options(**bad)
  with pytest.raises(errors.UserError, match='need a model'):
    options_lib.Options().describing(None)
  assert options_lib.Options(descriptor='fpfh').describing(object()) is None


@pytest.mark.real_data
def test_verification_aligns_only_the_candidates_that_could_win(monkeypatch):
  """The true pose (0.4 m off) and four poses 10-30 m off: ICP aligns the first, coarse
  then fine, and none of the others, whose share of cloud 2 within PRESCORE_DISTANCE of
  cloud 1 is below the aligned pose's share within FIT_DISTANCE."""
  scan = io.read_cloud(shared_path('kitti_object_velodyne', '000000.bin')).astype(np.float64)
  t_true = geometry.make_transform(geometry.rotation_z(np.radians(60.0)), np.array([5.0, 2.0, 0.0]))
  cloud2 = (scan[1::2] - t_true[:3, 3]) @ t_true[:3, :3]
  near = t_true @ geometry.make_transform(np.eye(3), np.array([0.3, -0.25, 0.0]))
  far = [t_true @ geometry.make_transform(geometry.rotation_z(np.radians(a)), np.array([d, 0, 0]))
         for a, d in ((0, 10.0), (30, 15.0), (90, 20.0), (180, 30.0))]
  calls = []
  original = icp.point_to_plane
  monkeypatch.setattr(icp, 'point_to_plane',
                      lambda *a, **k: calls.append(len(a[1])) or original(*a, **k))
  best, refined, fitness = verification.verify(scan[::2], cloud2, np.stack([*far[:2], near, *far[2:]]))
  assert best == 2 and len(calls) == 2                     # coarse, then fine, of one pose
  assert calls[0] <= verification.COARSE_POINTS < calls[1]
  err = metrics.registration_errors(t_true, refined[best])
  assert err['rte'] < 0.05 and err['rre_geodesic'] < 0.2, err
  assert fitness[best] > 0.8 and np.all(np.delete(fitness, best) < 0.3)
  np.testing.assert_array_equal(np.delete(refined, best, 0), np.stack(far))   # left as they were


@pytest.mark.real_data
def test_the_pose_verification_picks_by_another_rule_is_refined_in_full():
  """`choose` (the pipeline picks by fitness less free-space conflict) may pick a pose that
  was not refined in full: it is, before it is returned, as the best one is (a coarse pose
  can stop degrees off where the full ICP reaches the truth)."""
  scan = io.read_cloud(shared_path('kitti_object_velodyne', '000000.bin')).astype(np.float64)
  t_true = geometry.make_transform(geometry.rotation_z(np.radians(60.0)), np.array([5.0, 2.0, 0.0]))
  cloud2 = (scan[1::2] - t_true[:3, 3]) @ t_true[:3, :3]
  near = t_true @ geometry.make_transform(geometry.rotation_z(np.radians(3.0)),
                                          np.array([0.3, -0.25, 0.0]))
  other = t_true @ geometry.make_transform(geometry.rotation_z(np.radians(4.0)),
                                           np.array([4.0, 1.0, 0.0]))
  target, source = verification.target(scan[::2]), verification.source(cloud2)
  memo = {}
  by_fitness = verification.verify(target, source, np.stack([near, other]), memo=memo)
  assert by_fitness[0] == 0 and not np.array_equal(by_fitness[1][0], near)
  held = by_fitness[1][1]                                  # not refined in full
  assert ('fine', held.tobytes()) not in memo
  picked = []
  best, refined, fitness = verification.verify(
      target, source, np.stack([near, other]), memo=memo,
      choose=lambda poses, fit: picked.append(fit[1]) or 1)
  full, _ = icp.point_to_plane(target, source.points, held, verification.ICP_DISTANCES,
                               verification.ICP_ITERATIONS)
  assert best == 1 and len(picked) == 2                    # picked, refined, picked again
  np.testing.assert_array_equal(refined[1], full)
  assert fitness[1] == verification.fitness(target, source.scored, full)


@pytest.mark.real_data
def test_verification_sharing_a_memo_repeats_no_icp_and_gives_the_same_result(monkeypatch):
  """RANSAC's candidates verified, then those and more with the same memo (as
  pair_stages.verify does before and after the BEV search): the second call aligns only
  what the first did not, and its answer is that of one call on all candidates."""
  scan = io.read_cloud(shared_path('kitti_object_velodyne', '000000.bin')).astype(np.float64)
  t_true = geometry.make_transform(geometry.rotation_z(np.radians(-30.0)), np.array([4.0, 1.0, 0.0]))
  cloud2 = (scan[1::2] - t_true[:3, 3]) @ t_true[:3, :3]
  moved = lambda yaw, x: t_true @ geometry.make_transform(geometry.rotation_z(np.radians(yaw)),
                                                          np.array([x, 0.4, 0.0]))
  first = np.stack([moved(0.0, 6.0), moved(3.0, 0.8), moved(-2.0, -5.0)])
  more = np.concatenate([first, np.stack([moved(1.0, 0.2), moved(90.0, 12.0)])])
  target, source = verification.target(scan[::2]), verification.source(cloud2)
  calls = []
  original = icp.point_to_plane
  monkeypatch.setattr(icp, 'point_to_plane',
                      lambda *a, **k: calls.append(1) or original(*a, **k))
  alone = verification.verify(target, source, more)
  in_one = len(calls)
  memo = {}
  verification.verify(target, source, first, memo=memo)
  calls.clear()
  again = verification.verify(target, source, first, memo=memo)
  assert not calls                                         # everything was kept
  both = verification.verify(target, source, more, memo=memo)
  assert len(calls) <= in_one
  assert again[0] == verification.verify(target, source, first)[0]
  assert both[0] == alone[0]
  np.testing.assert_array_equal(both[1], alone[1])
  np.testing.assert_array_equal(both[2], alone[2])
  assert metrics.registration_errors(t_true, both[1][both[0]])['rte'] < 0.05


@pytest.mark.real_data
@pytest.mark.slow
def test_coarse_to_fine_ends_at_a_confident_coarse_pose_and_else_registers_as_without_it(
    tmp_path, monkeypatch):
  """A pair whose coarse level (the first 512 farthest-point keypoints) gives a confident
  verified pose ends there, half of each cloud's keypoints described; where no pose is
  confident enough the full level decides, to exactly the pose of a registration
  without levels."""
  paths, truth = _views(tmp_path)
  model = options_lib.verified_model(pretrained.load('ours'))
  registrar = pipeline.Registrar(np.load, model=model, say=lambda line: None)
  reg, f1, _ = registrar.register(paths['a'], paths['b'])
  assert reg.levels_tried == 1 and len(f1.xyz) == cloud_features.COARSE_KEYPOINTS
  assert reg.verified_fitness.max() >= verification.CONFIDENT_FITNESS
  for path in (paths['a'], paths['b']):
    levels = registrar.cloud(path)[0].features['learned']
    assert len(levels.described()) == cloud_features.COARSE_KEYPOINTS < len(levels.idx)
  assert metrics.registration_errors(truth['b'], reg.transform)['success']

  monkeypatch.setattr(verification, 'CONFIDENT_FITNESS', 1.01)   # never confident
  # The candidates' stages compared; the trusted pose's polish after them has its own test.
  monkeypatch.setattr(pair_stages, 'polish', lambda reg, *args, **kwargs: reg)
  fine = pipeline.Registrar(np.load, model=model, say=lambda line: None)
  reg_fine, g1, _ = fine.register(paths['a'], paths['b'])
  entries = [fine.cloud(p)[0] for p in (paths['a'], paths['b'])]
  levels = [e.features['learned'] for e in entries]
  assert reg_fine.levels_tried == 2 and len(g1.xyz) == len(levels[0].idx)
  one_level, _, _ = pair_stages.coarse_to_fine(
      levels[0].levels[-1:], levels[1].levels[-1:], entries[0].points, entries[1].points,
      candidates=10, bev_candidates=5)
  np.testing.assert_array_equal(reg_fine.transform, one_level.transform)
  assert metrics.registration_errors(truth['b'], reg_fine.transform)['success']


@pytest.mark.real_data
def test_verification_for_a_confident_pose_only_refines_none_far_from_confidence(tmp_path):
  """Where only a confident pose is of use, candidates that fit far below it after the
  coarse ICP are not refined in full; a right one is, as without the option."""
  paths, truth = _views(tmp_path)
  target, source = verification.target(np.load(paths['a'])), verification.source(np.load(paths['b']))
  wrong = truth['b'] @ geometry.make_transform(geometry.rotation_z(np.radians(90.0)),
                                               np.array([15.0, 0.0, 0.0]))
  memo = {}
  _, _, fit = verification.verify(target, source, wrong[None], memo=memo, confident_only=True)
  assert fit[0] < verification.CONFIDENT_FITNESS - verification.UNREFINED_MARGIN
  assert not any(kind == 'fine' for kind, _ in memo)
  near = truth['b'] @ geometry.make_transform(geometry.rotation_z(np.radians(2.0)),
                                              np.array([0.4, 0.0, 0.0]))
  best, refined, fit = verification.verify(target, source, np.stack([wrong, near]),
                                           confident_only=True)
  alone = verification.verify(target, source, np.stack([wrong, near]))
  assert best == 1 and fit[1] >= verification.CONFIDENT_FITNESS
  np.testing.assert_array_equal(refined[1], alone[1][1])


def test_a_confident_pose_ends_the_search_only_when_clearly_best():
  """Confident (>= CONFIDENT_FITNESS) and no pose 2 m / 5 degrees away within FINE_MARGIN:
  a near copy of the best does not count against it, a distinct runner-up does."""
  shifted = lambda x, yaw=0.0: geometry.make_transform(geometry.rotation_z(np.radians(yaw)),
                                                      np.array([x, 0.0, 0.0]))
  best = verification.CONFIDENT_FITNESS + 0.3
  close = best - verification.FINE_MARGIN / 2
  assert verification.clearly_confident(np.stack([shifted(0), shifted(0.3, 1.0)]),
                                        np.array([best, close]))
  assert not verification.clearly_confident(np.stack([shifted(0), shifted(1.8, 13.0)]),
                                            np.array([best, close]))
  assert verification.clearly_confident(np.stack([shifted(0), shifted(1.8, 13.0)]),
                                        np.array([best, best - 2 * verification.FINE_MARGIN]))
  assert not verification.clearly_confident(shifted(0)[None],
                                            np.array([verification.CONFIDENT_FITNESS - 0.01]))
