"""The weakly supervised 3DFeat-Net baseline: triplet loss, triplet data, stage hand-over,
the self-supervised detector and keypoint repeatability."""

import dataclasses
import json
import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import spatial

from ssd_jax import augment, geometry, inference, objective, train
from ssd_jax.config_tools import checks
from ssd_jax.configs.training import ours as ours_config
from ssd_jax.configs.training import feat3dnet as feat3dnet_config
from ssd_jax.data import clean, datasets, io, kitti
from ssd_jax.evaluation import orientation, repeatability

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_attention_weighted_triplet_by_hand():
  s = np.sqrt(0.5)
  # anchor clusters a0 = (1, 0), a1 = (0, 1); positive holds (1, 0) and (s, s);
  # negative holds (s, s) and (-1, 0); the negative's second cluster is masked out.
  desc = jnp.array([[[1.0, 0.0], [0.0, 1.0]],
                    [[1.0, 0.0], [s, s]],
                    [[s, s], [-1.0, 0.0]]])
  attention = jnp.array([[np.log(3.0), 0.0], [0.0, 0.0], [0.0, 0.0]])
  mask = jnp.array([[True, True], [True, True], [True, False]])
  loss, stats = objective.attention_weighted_triplet(desc, attention, mask, 0.2, 'cluster')
  d_sq = np.sqrt(2 - 2 * s)              # distance between (1, 0) and (s, s), also (0, 1)-(s, s)
  d_pos = np.array([0.0, d_sq])          # a0 matches exactly, a1's best is (s, s)
  d_neg = np.array([d_sq, d_sq])         # only (s, s) is valid in the negative
  w = np.exp([np.log(3.0), 0.0]) / 4.0   # softmax of the anchor attention: 0.75, 0.25
  expected = np.sum(w * np.maximum(d_pos - d_neg + 0.2, 0.0))   # 0.75 * 0 + 0.25 * 0.2
  assert float(loss) == pytest.approx(expected, abs=1e-5) and expected == pytest.approx(0.05)
  assert float(stats['triplet_accuracy']) == pytest.approx(0.75)
  grad = jax.grad(
      lambda a: objective.attention_weighted_triplet(desc, a, mask, 0.2, 'cluster')[0])(attention)
  assert float(grad[0, 0]) < 0 < float(grad[0, 1])   # attention moves to the cluster that matches

  # 3DFeat-Net's released code: softplus attention divided by its sum, one hinge on the
  # weighted sums. Attention (1, 3) -> w = (0.25, 0.75).
  attention = jnp.array([[1.0, 3.0], [0.0, 0.0], [0.0, 0.0]])
  def loss_of(a, hinge, m=mask):
    return objective.attention_weighted_triplet(desc, a, m, 0.2, hinge, 'sum')[0]
  w = np.array([0.25, 0.75])
  cloud = max(np.sum(w * d_pos) - np.sum(w * d_neg) + 0.2, 0.0)     # 0.2 - 0.25 * d_sq
  assert float(loss_of(attention, 'cloud')) == pytest.approx(cloud, abs=1e-5)
  assert cloud == pytest.approx(0.2 - 0.25 * d_sq) and cloud > 0
  assert float(loss_of(attention, 'cluster')) == pytest.approx(0.75 * 0.2, abs=1e-5)
  grad = jax.grad(lambda a: loss_of(a, 'cloud'))(attention)
  assert float(grad[0, 0]) < 0 < float(grad[0, 1])
  # A masked anchor cluster gets no weight: only a0 counts, d_pos - d_neg + 0.2 < 0.
  anchor_a0 = mask.at[0, 1].set(False)
  assert float(loss_of(attention, 'cloud', anchor_a0)) == 0.0
  with pytest.raises(ValueError, match="hinge must be 'cluster' or 'cloud'"):
    loss_of(attention, 'triplet')


def test_triplet_dataset_draws_valid_triplets(synthetic_root):
  data = datasets.TripletDataset(synthetic_root / 'train')
  entries = io.read_oxford_index(synthetic_root / 'train' / 'train.txt')
  for a in data.anchors:
    assert set(data.positives[a]) == set(entries[a].positives)
    banned = {a, *entries[a].positives, *entries[a].non_negatives}
    assert not banned & set(data.negatives[a].tolist()) and len(data.negatives[a])
  b1 = data.batch(0, 3, 2, 256)
  assert b1.shape == (2, 3, 256, 3)
  np.testing.assert_array_equal(b1, data.batch(0, 3, 2, 256))
  assert not np.array_equal(b1, data.batch(0, 4, 2, 256))
  np.testing.assert_array_equal(data.batch(0, 3, 2, 256, rows=[1]), b1[1:])   # one process's rows
  with pytest.raises(clean.CloudDataError, match='needs a 3DFeat-Net train.txt'):
    datasets.TripletDataset(synthetic_root / 'test_kitti' / '00')


def test_self_positives_control(synthetic_root):
  """positives='self': each cloud's positive is the same scan, subsampled afresh;
  the negatives stay those of the index."""
  indexed = datasets.TripletDataset(synthetic_root / 'train')
  control = datasets.TripletDataset(synthetic_root / 'train', positives='self')
  assert [p.tolist() for p in control.positives] == [[i] for i in range(len(control.positives))]
  for a in indexed.anchors:
    np.testing.assert_array_equal(control.negatives[a], indexed.negatives[a])
  anchor, positive, negative = control.batch(0, 0, 1, 512)[0]
  scans = ({tuple(p) for p in control.clouds.cloud(int(i)).round(4)} for i in control.anchors)
  scan = next(s for s in scans if tuple(anchor[0].round(4)) in s)
  assert all(tuple(p) in scan for p in positive.round(4))   # drawn from the anchor's scan
  assert not np.array_equal(np.sort(anchor, 0), np.sort(positive, 0))   # a different draw
  assert not any(tuple(p) in scan for p in negative.round(4)[:20])
  with pytest.raises(clean.CloudDataError, match='positives must be one of'):
    datasets.TripletDataset(synthetic_root / 'train', positives='nearest')


def test_triplet_clouds_share_their_scene_axes(synthetic_root):
  """Anchor and positive, rotated into scene axes, differ by their sensors' offset
  only; as stored (sensor frames) they also differ by the heading change."""
  scene = datasets.TripletDataset(synthetic_root / 'train', crop_radius=0)
  stored = datasets.TripletDataset(synthetic_root / 'train', axes='stored', crop_radius=0)
  position = lambda f: kitti.read_poses(f.parent / 'poses.txt')[int(f.stem), :3, 3]
  gaps = {}
  for name, data in (('scene', scene), ('stored', stored)):
    a = int(data.anchors[0])
    p = int(data.positives[a][0])
    files = data.clouds.files
    cloud_a = data.clouds.cloud(a) + position(files[a])
    cloud_p = data.clouds.cloud(p) + position(files[p])
    gaps[name] = np.median(spatial.cKDTree(cloud_p).query(cloud_a)[0])
  assert gaps['scene'] < 0.25 < gaps['stored'], gaps    # voxel 0.2 m vs. metres apart
  with pytest.raises(clean.CloudDataError, match='axes must be one of'):
    datasets.TripletDataset(synthetic_root / 'train', axes='world')


def test_scene_axes_need_frame_numbered_files(synthetic_root, tmp_path):
  folder = tmp_path / '00'
  folder.mkdir()
  (folder / 'poses.txt').write_text((synthetic_root / 'train' / '00' / 'poses.txt').read_text())
  (folder / 'scan_a.bin').write_bytes((synthetic_root / 'train' / '00' / '000000.bin').read_bytes())
  with pytest.raises(clean.CloudDataError, match='named by its frame number'):
    datasets.scene_rotations([folder / 'scan_a.bin'])
  assert datasets.scene_rotations([synthetic_root / 'clusters' / 'does_not_matter.bin']) == [None]


def _triplet_config(tiny_config, root, stage):
  config = tiny_config
  config.objective = 'triplet'
  config.data.path = str(root / 'train')
  config.model.use_orientation = stage == 'full'
  config.model.augmentations = (('jitter', 'rotate_small', 'shift') if stage == 'pretrain'
                                else ('jitter', 'rotate_small', 'shift', 'rotate_1d'))
  return config


@pytest.mark.slow
def test_stages_hand_over_descriptor_and_fresh_detector(tiny_config, synthetic_root, tmp_path):
  pre = _triplet_config(tiny_config, synthetic_root, 'pretrain')
  pre.train.num_steps = 2
  pre_state = train.train_and_evaluate(pre, str(tmp_path / 'pre'))
  assert 'detector' not in pre_state.params     # stage 1 has no detector
  with open(tmp_path / 'pre' / 'metrics.jsonl') as f:
    records = [json.loads(line) for line in f]
  probes = {r['step']: r['probe_loss'] for r in records if 'probe_loss' in r}
  assert sorted(probes) == [0, 2]
  # Step 0's probe is the untrained state's triplet loss on the fixed probe triplets.
  data = datasets.TripletDataset(pre.data.path, min_points=pre.data.min_points)
  probe = data.batch(pre.seed + 1, 0, pre.train.batch_size * objective.PROBE_BATCHES,
                     pre.data.num_points)
  untrained = train.create_train_state(pre, jax.random.key(pre.seed))
  model = train.create_model(pre)
  expected = train.probe_step(untrained, jnp.asarray(probe), jax.random.key(pre.seed + 2),
                              model=model, config=pre)
  assert probes[0] == pytest.approx(float(expected['loss']), rel=1e-5)
  # ... the mean over its batches, each with its own draw of augmentations and centres.
  b = pre.train.batch_size
  keys = jax.random.split(jax.random.key(pre.seed + 2), objective.PROBE_BATCHES)
  one_batch = jax.jit(lambda p, k: train.eval_step(untrained, p, k, model=model, config=pre,
                                                   objective_name='triplet')['loss'])
  per_batch = [float(one_batch(jnp.asarray(probe[i * b:(i + 1) * b]), keys[i]))
               for i in range(objective.PROBE_BATCHES)]
  assert probes[0] == pytest.approx(np.mean(per_batch), rel=1e-4)
  assert np.std(per_batch) > 1e-3   # the draws differ
  with pytest.raises(ValueError, match='not a multiple of the training batch size'):
    train.probe_step(untrained, jnp.asarray(probe[:b + 1]), jax.random.key(0), model=model,
                     config=pre)
  full = _triplet_config(tiny_config.copy_and_resolve_references(), synthetic_root, 'full')
  fresh = train.create_train_state(full, jax.random.key(full.seed))
  handed = train.initialize_from(jax.device_get(fresh), str(tmp_path / 'pre'), full)
  jax.tree.map(np.testing.assert_array_equal, handed.params['descriptor'],
               jax.device_get(pre_state.params['descriptor']))
  jax.tree.map(np.testing.assert_array_equal, handed.batch_stats['descriptor'],
               jax.device_get(pre_state.batch_stats['descriptor']))
  jax.tree.map(np.testing.assert_array_equal, handed.params['detector'], fresh.params['detector'])
  with pytest.raises(checks.ConfigError, match='train.init_from: .*no such checkpoint'):
    train.initialize_from(fresh, str(tmp_path / 'nowhere'), full)
  # ... and through the training entry: stage 2 starts from stage 1's descriptor.
  full.train.num_steps, full.train.init_from = 2, str(tmp_path / 'pre')
  full.train.learning_rate = 1e-12   # two steps that barely move the weights
  state = jax.device_get(train.train_and_evaluate(full, str(tmp_path / 'full')))
  np.testing.assert_allclose(state.params['descriptor']['out']['kernel'],
                             pre_state.params['descriptor']['out']['kernel'], atol=1e-6)


@pytest.mark.parametrize('override, message', [
    (dict(objective='contrastive'), 'objective must be one of'),
    (dict(augmentations=('jitter', 'flip')), "model.augmentations: unknown \\['flip'\\]"),
    (dict(attention_in_cf=True, use_orientation=False), 'attention_in_cf needs'),
    (dict(triplet_axes='world'), 'data.triplet_axes must be one of'),
    (dict(triplet_positives='nearest'), 'data.triplet_positives must be one of'),
])
def test_baseline_config_errors(tiny_config, override, message):
  for key, value in override.items():
    if key == 'objective':
      tiny_config.objective = value
    elif key.startswith('triplet_'):
      tiny_config.data[key] = value
    else:
      tiny_config.model[key] = value
  with pytest.raises(checks.ConfigError, match=message):
    checks.check_config(tiny_config)


def _attention_grad(config):
  model = train.create_model(config)
  state = train.create_train_state(config, jax.random.key(0))
  pts = jnp.asarray(np.random.default_rng(0).uniform(-8, 8, (2, 512, 3)) * [1, 1, 0.25],
                    jnp.float32)

  def loss(params):
    variables = {'params': params, 'batch_stats': state.batch_stats}
    return objective.self_supervised_loss(model, variables, jax.random.key(1), pts,
                                          jnp.ones(pts.shape[:2], bool), config.model)[0]
  return jax.jit(jax.grad(loss))(state.params)['detector']['attention']['kernel']


@pytest.mark.slow
def test_self_supervised_detector_trains_attention_only_when_on(tiny_config):
  assert float(jnp.abs(_attention_grad(tiny_config)).max()) == 0.0   # the paper: no gradient
  tiny_config.model.attention_in_cf = True
  assert float(jnp.abs(_attention_grad(tiny_config)).max()) > 1e-6


def test_keypoint_repeatability_by_hand():
  t12 = np.asarray(geometry.make_transform(np.asarray(geometry.rotation_z(np.pi / 2)),
                                           np.array([1.0, 0, 0])))
  kp2 = np.array([[0.0, 0, 0], [2, 0, 0]])          # land at (1, 0, 0) and (1, 2, 0)
  kp1 = np.array([[1.0, 0.4, 0], [1, 2.6, 0], [3, 0, 0], [1, 1.9, 0.1]])
  assert repeatability.keypoint_repeatability(kp1, kp2, t12) == pytest.approx(0.5)
  assert repeatability.keypoint_repeatability(kp1, kp2[:0], t12) == 0.0
  assert np.isnan(repeatability.keypoint_repeatability(kp1[:0], kp2, t12))


def test_orientation_error_wraps_around():
  theta = np.radians([10.0, 350.0, 0.0])
  turned = np.radians([100.0, 80.0, 270.0])
  # after a 90 deg turn: exact; 350 + 90 = 440 = 80 (exact); 0 + 90 vs 270: 180 off
  np.testing.assert_allclose(orientation.orientation_error_deg(theta, turned, np.pi / 2),
                             [0.0, 0.0, 180.0], atol=1e-9)


def test_orientation_needs_a_detector(tiny_config):
  state = train.create_train_state(tiny_config, jax.random.key(0))
  model = inference.Model.from_config(tiny_config, {'params': state.params,
                                                    'batch_stats': state.batch_stats})
  points = np.random.default_rng(0).uniform(-8, 8, (600, 3)).astype(np.float32)
  stage1 = dataclasses.replace(model, net=train.create_model(tiny_config).clone(
      use_orientation=False))
  with pytest.raises(ValueError, match='has no detector'):
    inference.detect_at(stage1, points, points[:4])


def test_reference_augmentations_act_per_cloud():
  """RotateSmall, Shift and Rotate1D: one rigid motion per cloud, within the reference's
  bounds, different between the clouds of a batch."""
  pts = jnp.asarray(np.random.default_rng(0).uniform(-10, 10, (4, 200, 3)), jnp.float32)
  key = jax.random.key(3)

  def fitted_rotation(a, b):   # least squares b = a @ M (exact for a pure linear map)
    return np.linalg.lstsq(np.asarray(a, np.float64), np.asarray(b, np.float64), rcond=None)[0]

  small = augment.rotate_small(key, pts)
  one_d = augment.rotate_1d(key, pts)
  angles = []
  for c in range(4):
    m = fitted_rotation(pts[c], small[c])
    np.testing.assert_allclose(m.T @ m, np.eye(3), atol=1e-4)     # a rotation, no scaling
    # three angles each clipped to 0.18 rad: the total turn stays below sqrt(3) * 0.18
    assert np.degrees(np.arccos(np.clip((np.trace(m) - 1) / 2, -1, 1))) < np.degrees(0.32)
    r = fitted_rotation(pts[c], one_d[c])
    np.testing.assert_allclose(r[:, 2], [0, 0, 1], atol=1e-4)     # about z only
    angles.append(np.arctan2(r[0, 1], r[0, 0]))
  assert len(np.unique(np.round(angles, 3))) == 4                  # a draw per cloud
  moved = np.asarray(augment.shift(key, pts) - pts)
  assert np.abs(moved).max() <= 0.1 + 1e-6
  np.testing.assert_allclose(moved, np.broadcast_to(moved[:, :1], moved.shape), atol=1e-5)
  assert not np.allclose(moved[0, 0], moved[1, 0])


def test_rotate_1d_draws_over_the_whole_circle():
  """Rotate1D turns each cloud by a uniform angle in [-180, 180) degrees: every quarter of
  the circle gets about a quarter of 4,000 clouds, and turns beyond +-170 degrees occur."""
  pts = jnp.tile(jnp.array([[[1.0, 0.0, 0.0]]]), (4000, 1, 1))
  turned = np.asarray(augment.rotate_1d(jax.random.key(0), pts))[:, 0]
  angle = np.degrees(np.arctan2(turned[:, 1], turned[:, 0]))
  quarters = np.histogram(angle, bins=[-180, -90, 0, 90, 180])[0] / len(angle)
  np.testing.assert_allclose(quarters, 0.25, atol=0.03)
  assert np.abs(angle).max() > 170.0


@pytest.mark.parametrize('head', ['mlp', 'equivariant'])
def test_triplet_loss_reaches_the_orientation_head_in_stage_2(tiny_config, head):
  """Stage 2's triplet loss (Rotate1D on) gives the orientation head's weights a gradient,
  for 3DFeat-Net's MLP head and for the head that turns with the cluster."""
  config = tiny_config
  config.objective = 'triplet'
  config.model.orientation_head = head
  config.model.augmentations = ('jitter', 'rotate_small', 'shift', 'rotate_1d')
  model = train.create_model(config)
  state = train.create_train_state(config, jax.random.key(0))
  rng = np.random.default_rng(0)
  pts = jnp.asarray(rng.uniform(-8, 8, (2, 3, 512, 3)) * [1, 1, 0.25], jnp.float32)

  def loss(params):
    variables = {'params': params, 'batch_stats': state.batch_stats}
    return objective.triplet_loss(model, variables, jax.random.key(1), pts,
                                  jnp.ones(pts.shape[:3], bool), config.model)[0]
  grads = jax.jit(jax.grad(loss))(state.params)['detector']['orientation']
  assert all(float(jnp.abs(g).max()) > 1e-7 for g in jax.tree.leaves(grads))


def test_architecture_matched_baseline_shares_ours_network_and_budget():
  """configs/training/feat3dnet.py trains `ours`' network (configs/training/ours.py) on the same
  clouds for the same steps; only the objective and its augmentations differ."""
  ours, baseline = ours_config.get_config(), feat3dnet_config.get_config()
  assert baseline.objective == 'triplet' and ours.objective != 'triplet'
  for key in ('radius', 'orientation_head', 'num_clusters', 'num_samples', 'descriptor_dim'):
    assert baseline.model[key] == ours.model[key], key
  for section, key in (('data', 'path'), ('data', 'num_points'), ('train', 'num_steps'),
                       ('train', 'lr_schedule'), ('train', 'learning_rate')):
    assert baseline[section][key] == ours[section][key], (section, key)
  assert baseline.inference.to_dict() == ours.inference.to_dict()
  assert 'rotate_1d' in baseline.model.augmentations
  checks.check_config(baseline)
  checks.check_config(feat3dnet_config.get_config('pretrain'))
