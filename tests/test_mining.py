"""Label-free training pairs (registration.mining, data.mined_pairs) and the two-view
training data made of them (datasets.MinedPairDataset)."""

import dataclasses
import functools

import numpy as np
import pytest
from scipy import spatial

from ssd_jax import geometry, pretrained
from ssd_jax.infra import errors
from ssd_jax.data import clean, datasets, groundtruth, kitti, mined_pairs
from ssd_jax.adaptation import mining
from ssd_jax.synthetic import cross_sensor
from tests.conftest import tiny_cross_sensor_config


def _pose(yaw_deg, x, y):
  return geometry.make_transform(geometry.rotation_z(np.radians(yaw_deg)), np.array([x, y, 0.0]))


def _pair(poses, i, j, error=None):
  t = geometry.invert_transform(poses[i]) @ poses[j]
  if error is not None:
    t = t @ error
  return mined_pairs.MinedPair(f's{i}', f's{j}', j - i, t, 0.6, True)


def test_candidate_pairs_follow_capture_order():
  assert mining.candidate_pairs(5, (1, 2)) == [(0, 1), (0, 2), (1, 2), (1, 3), (2, 3), (2, 4),
                                               (3, 4)]
  with pytest.raises(errors.UserError, match='positive'):
    mining.candidate_pairs(5, (0, 1))


def test_the_gate_keeps_the_pairs_of_consistent_loops_only():
  poses = [_pose(10 * k, 6.0 * k, 0.5 * k) for k in range(6)]
  index = {f's{k}': k for k in range(6)}
  shifted = _pose(0, 1.5, 0)   # a wrong label: 1.5 m off
  pairs = [_pair(poses, 0, 1), _pair(poses, 1, 2), _pair(poses, 0, 2),
           _pair(poses, 2, 3), _pair(poses, 3, 4), _pair(poses, 2, 4, error=shifted),
           _pair(poses, 4, 5)]
  pairs.append(dataclasses.replace(_pair(poses, 3, 5), confident=False,
                                   reason='no confident pose'))
  mining.apply_gate(pairs, index)
  kept = {(p.cloud1, p.cloud2): p.kept for p in pairs}
  # (0, 1, 2) closes; (2, 3, 4) does not (the long side is 1.5 m off); (4, 5) is in no loop.
  assert kept == {('s0', 's1'): True, ('s1', 's2'): True, ('s0', 's2'): True,
                  ('s2', 's3'): False, ('s3', 's4'): False, ('s2', 's4'): False,
                  ('s4', 's5'): False, ('s3', 's5'): False}
  assert {p.reason for p in pairs if not p.kept} == {'in no consistent loop',
                                                     'no confident pose'}
  rot, trans = mining.cycle_error(pairs[3].transform, pairs[4].transform, pairs[5].transform)
  assert rot < 1e-6 and trans == pytest.approx(1.5)


@pytest.fixture(scope='module')
def drive(tmp_path_factory):
  """The first 5 scans of a simulated VLP-16 drive (10 m apart), their poses, and the pairs
  mined from them (gaps 1 and 2) into mined.csv with every pose reader made to fail."""
  root = tmp_path_factory.mktemp('drive')
  scans, truth = root / 'scans', root / 'poses.txt'
  cross_sensor.write_sensor_scans(tiny_cross_sensor_config(), 'vlp16', scans, num_scenes=1,
                                  spacing=10.0, poses_out=truth)
  files = sorted(scans.glob('*.bin'))
  for f in files[5:]:
    f.unlink()
  poses = kitti.read_poses(truth)[:5]
  files = [str(f) for f in files[:5]]

  def no_pose(*args, **kwargs):
    raise AssertionError('mining or training read a pose')
  with pytest.MonkeyPatch.context() as patch:
    patch.setattr(kitti, 'read_poses', no_pose)
    patch.setattr(groundtruth, 'read_groundtruths', no_pose)
    path = str(root / 'mined.csv')
    pairs = mining.mine_to_file(path, files, functools.partial(clean.read_metres, fmt='auto'),
                                gaps=(1, 2), say=lambda s: None)
    kept = mined_pairs.read_kept(path)
    ds = datasets.MinedPairDataset(files, kept, rate=1.0, crop_radius=20.0)
    batches = [ds.batch(0, 0, 4, 2048), ds.batch(0, 0, 4, 2048)]
  return files, poses, path, pairs, ds, batches


def test_mined_labels_are_right_and_read_no_pose(drive):
  scans, poses, _, pairs, ds, batches = drive
  kept = [p for p in pairs if p.kept]
  assert len(pairs) == 7 and len(kept) >= 5
  e = mining.label_errors(kept, poses, {s: n for n, s in enumerate(scans)})
  assert e['success'].all() and np.median(e['rte']) < 0.2 and np.median(e['rre']) < 1.0
  # Two-view training data: the second view lies on the first where the scans overlap.
  assert batches[0].shape == (4, 2, 2048, 3)
  np.testing.assert_array_equal(batches[0], batches[1])
  view1, view2 = ds.views(0)
  near = spatial.cKDTree(view1).query(view2, distance_upper_bound=0.5)[0]
  assert np.isfinite(near).mean() > 0.3


def test_chained_pairs_are_right_and_far_pairs_are_drawn_by_distance(drive, monkeypatch):
  scans, poses, _, pairs, _, _ = drive
  near = [p for p in pairs if p.kept and p.gap == 1]
  assert len(near) >= 3
  chain = mined_pairs.chained(near, 3)
  assert {p.gap for p in chain} == {1, 2, 3} and len(chain) > len(near)
  e = mining.label_errors(chain, poses, {s: n for n, s in enumerate(scans)})
  assert e['success'].all() and np.median(e['rte']) < 0.3, e
  # A pair the miner kept stays as it found it; chaining them all adds only farther ones.
  every = mined_pairs.chained([p for p in pairs if p.kept], 2)
  for p in pairs:
    if p.kept:
      assert any(q is p for q in every)
  # 'distance': each row picks a pair with chance in proportion to how far apart it is.
  files = scans
  far = datasets.MinedPairDataset(files, chain, rate=1.0, crop_radius=20.0, weight='distance')
  picked = []
  monkeypatch.setattr(far, 'views', lambda k, flip=False: (picked.append(k), (
      np.zeros((2000, 3), np.float32),) * 2)[1])
  for step in range(200):
    far.batch(0, step, 4, 64)
  apart = np.array([np.linalg.norm(p.transform[:3, 3]) for p in chain])
  share = np.bincount(picked, minlength=len(chain)) / len(picked)
  np.testing.assert_allclose(share, apart / apart.sum(), atol=0.04)
  with pytest.raises(ValueError, match='weight must be one of'):
    datasets.MinedPairDataset(files, chain, rate=1.0, weight='far')


def test_workers_find_the_same_pairs_and_a_rerun_registers_none(drive, monkeypatch):
  scans, _, path, pairs, _, _ = drive
  calls = []
  # Gap 1 of the first 4 scans, in 3 chunks over 2 processes: the poses found by one.
  monkeypatch.setattr(mining, 'CHUNK', 1)
  two = mining.mine(scans[:4], functools.partial(clean.read_metres, fmt='auto'), gaps=(1,),
                    say=lambda s: None, workers=2)
  one = {(p.cloud1, p.cloud2): p for p in pairs}
  assert len(two) == 3
  for p in two:
    assert (p.confident, p.fitness) == (one[p.cloud1, p.cloud2].confident,
                                        one[p.cloud1, p.cloud2].fitness)
    np.testing.assert_array_equal(p.transform, one[p.cloud1, p.cloud2].transform)
  again = mined_pairs.PairsFile(path)
  assert set(again.done) == set(one)
  mining.mine(scans, lambda p: calls.append(p) or clean.read_metres(p, 'auto'), gaps=(1, 2),
              done=again.done, say=lambda s: None)
  assert calls == []


def test_a_drive_of_far_apart_keyframes_is_mined_at_a_shorter_stride(monkeypatch):
  """A teacher that registers scans up to 6 apart: every 4th of 457 scans (120 at most)
  leaves loop sides 8 apart, which it cannot register, so the stride halves to 2; one that
  registers 8 apart keeps 4. Each try probes MIN_PROBE pairs two strides apart."""
  scans = [f's{k:03d}' for k in range(457)]
  probed = []

  def teacher(reach):
    def register_many(pairs, read, options, say):
      probed.append([int(b[1:]) - int(a[1:]) for a, b in pairs])
      return [(a, b, int(b[1:]) - int(a[1:]) <= reach) for a, b in pairs]
    return register_many
  judged = lambda result, gap: mined_pairs.MinedPair(result[0], result[1], gap, np.eye(4),
                                                     0.5, result[2])
  monkeypatch.setattr(mining, '_judged', judged)
  monkeypatch.setattr(mining.pipeline, 'register_many', teacher(6))
  assert mining.stride_for(scans, None, 120, say=lambda line: None) == 2
  assert probed == [[8] * mining.MIN_PROBE, [4] * mining.MIN_PROBE]
  monkeypatch.setattr(mining.pipeline, 'register_many', teacher(8))
  assert mining.stride_for(scans, None, 120, say=lambda line: None) == 4


def test_a_long_drive_is_thinned_and_widening_doubles_the_reached_gap():
  scans = [f's{k:03d}' for k in range(457)]
  thinned = mining.spread(scans, 120)
  assert len(thinned) == 115 and thinned[:3] == ['s000', 's004', 's008']
  assert mining.spread(scans[:50], 120) == scans[:50]
  # At a shorter stride, the middle 120 of the drive's every other scan.
  assert mining.spread(scans, 120, 2) == scans[108:348:2]
  with pytest.raises(errors.UserError, match='max_scans must be 3 or more'):
    mining.spread(scans, 2)
  poses = [_pose(0, 2.0 * k, 0) for k in range(17)]
  pairs = [_pair(poses, 0, 2), _pair(poses, 0, 8)]
  pairs[0].kept = True
  assert mining.widened_gaps(pairs) == (4, 8)
  assert mining.widened_gaps(pairs[1:]) == ()
  # A gap whose probe failed with one pair kept of 8 (under MIN_YIELD) is widened to.
  probe = [_pair(poses, k, k + 8) for k in range(8)]
  probe[0].kept = True
  assert mining.widened_gaps(pairs + probe) == (4, 8)
  for p in probe[1:2]:
    p.kept = True
  assert mining.widened_gaps(pairs + probe) == (16, 32)


def test_a_learned_teacher_retries_the_pairs_the_classical_one_could_not(monkeypatch):
  """Mining with a model registers again, once, the done pairs that are not confident;
  without one, no done pair is registered again."""
  scans = [f's{k}' for k in range(6)]
  done = {(f's{k}', f's{k + 1}'): mined_pairs.MinedPair(f's{k}', f's{k + 1}', 1, np.eye(4), 0.1,
                                                          k % 2 == 0) for k in range(5)}
  registered = []

  def register_many(pairs, read, model, options, say):
    registered.append(list(pairs))
    return [(a, b) for a, b in pairs]
  monkeypatch.setattr(mining.pipeline, 'register_many', register_many)
  monkeypatch.setattr(mining, '_judged', lambda result, gap: mined_pairs.MinedPair(
      *result, gap, np.eye(4), 0.5, True))
  mining.mine(scans, None, gaps=(1,), model=object(), done=done, say=lambda s: None)
  assert sorted(p for batch in registered for p in batch) == [('s1', 's2'), ('s3', 's4')]
  registered.clear()
  mining.mine(scans, None, gaps=(1,), done=done, say=lambda s: None)
  assert not any(registered)


def test_a_widening_round_is_gated_with_the_labels_before_it(drive, tmp_path):
  """Gap 2 mined by the learned teacher into a file of the gap-1 labels: its pairs are
  kept through loops with them, right, and every earlier pair stays as it was."""
  scans, poses, path, pairs, _, _ = drive
  rows = open(path).read().splitlines()
  first = [rows[0]] + [r for r in rows[1:] if r.split(',')[2] == '1']
  widened = tmp_path / 'mined.csv'
  widened.write_text('\n'.join(first) + '\n')
  every = mining.mine_to_file(str(widened), scans, functools.partial(clean.read_metres,
                                                                     fmt='auto'),
                              gaps=(2,), model=pretrained.load('ours'), say=lambda s: None)
  before = {(p.cloud1, p.cloud2): p for p in pairs if p.gap == 1}
  far = [p for p in every if p.gap == 2]
  assert len(every) == 7 and len(far) == 3
  assert sum(p.kept for p in far) >= 2
  kept = [p for p in far if p.kept]
  assert mining.label_errors(kept, poses, {s: n for n, s in enumerate(scans)})['success'].all()
  for p in every:
    if p.gap == 1:
      np.testing.assert_allclose(p.transform, before[p.cloud1, p.cloud2].transform, atol=1e-9)
  assert len(mined_pairs.read_kept(str(widened))) == sum(p.kept for p in every)


def test_a_file_that_is_not_mined_pairs_is_one_line(tmp_path):
  bad = tmp_path / 'x.csv'
  bad.write_text('a,b\n')
  with pytest.raises(errors.UserError, match='not a file of mined pairs'):
    mined_pairs.read_kept(str(bad))
  with pytest.raises(errors.UserError, match='none.csv: no such file of mined pairs'):
    mined_pairs.read_kept(str(tmp_path / 'none.csv'))
