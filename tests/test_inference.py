"""Inference API: neighbourhoods as the ball query finds them, one compiled shape, NMS,
checkpoints."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import spatial

from ssd_jax import grouping, inference, network, train
from ssd_jax.configs.training import paper_small
from ssd_jax.data import io
from tests.conftest import shared_path


@pytest.fixture(scope='module')
def model():
  config = paper_small.get_config()
  config.model.num_samples = 16
  state = train.create_train_state(config, jax.random.key(0))
  return inference.Model.from_config(config, {'params': state.params,
                                              'batch_stats': state.batch_stats})


def _cloud(rng, n):
  ground = np.c_[rng.uniform(-15, 15, (n // 2, 2)), rng.normal(-1.7, 0.02, n // 2)]
  walls = np.c_[rng.uniform(-15, 15, n - n // 2), rng.choice([-6.0, 7.0], n - n // 2),
                rng.uniform(-1.7, 2.0, n - n // 2)]
  return np.concatenate([ground, walls]).astype(np.float32)


def test_kdtree_neighbourhoods_equal_ball_query(model):
  rng = np.random.default_rng(0)
  pts = rng.uniform(-3, 3, (2000, 3)).astype(np.float32)
  centers = np.concatenate([pts[:50], rng.uniform(-3, 3, (10, 3)), [[100.0, 0, 0]]]).astype(np.float32)
  ball = dataclasses.replace(model, radius=1.0, num_samples=32)
  idx, has = inference._neighbourhoods(ball, pts, centers, [0])
  perm = inference._permutation(len(pts), 0)
  ref_idx, ref_has = grouping.ball_query(pts[perm], centers, 1.0, 32)
  np.testing.assert_array_equal(has, np.asarray(ref_has))
  np.testing.assert_array_equal(idx[has], perm[np.asarray(ref_idx)[has]])
  assert not has[-1]


def test_descriptors_are_unit_vectors_and_attention_covers_every_point(model):
  rng = np.random.default_rng(1)
  pts = _cloud(rng, 3000)
  kp = pts[rng.choice(len(pts), 100, replace=False)]
  a = inference.describe(model, pts, kp, chunk=64)
  assert a.shape == (100, 32)
  np.testing.assert_allclose(np.linalg.norm(a, axis=1), 1.0, atol=1e-5)
  att, ori = inference.attention(model, pts, chunk=512)
  assert att.shape == ori.shape == (3000,) and np.all(att >= 0)
  # The attention at every point is the detector at those points as centres.
  at, ot = inference.detect_at(model, pts, pts[:10], chunk=512)
  np.testing.assert_allclose(at, att[:10], rtol=1e-5, atol=1e-6)
  np.testing.assert_allclose(ot, ori[:10], atol=1e-5)


def test_stream_of_clouds_compiles_the_network_once(model):
  rng = np.random.default_rng(2)
  inference.describe(model, _cloud(rng, 1500), _cloud(rng, 40), chunk=64)
  network_shapes = inference._network_kernel()._cache_size()
  # The network sees host-gathered clusters: one shape whatever the cloud size, for
  # descriptors and attention alike.
  for n, k in [(1100, 10), (1800, 64), (5000, 100), (9000, 130)]:
    out = inference.describe(model, _cloud(rng, n), _cloud(rng, k), chunk=64)
    assert out.shape == (k, 32)
  assert inference._network_kernel()._cache_size() == network_shapes
  inference.attention(model, _cloud(rng, 1500), chunk=256)
  detect_shapes = inference._network_kernel()._cache_size()
  att, ori = inference.attention(model, _cloud(rng, 5000), chunk=256)   # another size bucket
  assert att.shape == ori.shape == (5000,)
  assert inference._network_kernel()._cache_size() == detect_shapes


def test_cpu_compiler_options_leave_the_network_outputs_unchanged(model):
  """The network kernel's YNNPACK setting changes how XLA:CPU runs it, not what it
  computes: the same clusters give the same descriptors and detector outputs."""
  assert inference._compiler_options() == inference._CPU_COMPILER_OPTIONS
  rng = np.random.default_rng(4)
  pts = _cloud(rng, 4000)
  groups = pts[rng.integers(0, 4000, (300, 16))]
  centers, has = groups[:, 0].copy(), np.ones(300, bool)
  plain = jax.jit(inference._run_on_groups, static_argnames=('net', 'radius', 'what'))
  for what in ('describe', 'detect'):
    args = (model.net, model.variables, jnp.asarray(groups.reshape(-1, 3)), jnp.asarray(centers),
            jnp.arange(300 * 16, dtype=jnp.int32).reshape(300, 16), jnp.asarray(has))
    tuned = inference._network_kernel()(*args, radius=model.radius, what=what)
    reference = plain(*args, radius=model.radius, what=what)
    for a, b in zip(jax.tree.leaves(tuned), jax.tree.leaves(reference)):
      np.testing.assert_allclose(np.asarray(a), np.asarray(b), atol=2e-5)


def test_draws_sample_each_ball_as_a_shuffled_cloud_would():
  rng = np.random.default_rng(8)
  pts = _cloud(rng, 3000)
  centers = np.concatenate([pts[:40], [[500.0, 0, 0]]]).astype(np.float32)
  balls = [np.asarray(b, np.int64) for b in spatial.cKDTree(pts).query_ball_point(
      centers, np.nextafter(2.0, 0))]
  for order_seed in (0, (0, 1), 7):
    perm = inference._permutation(len(pts), order_seed)
    np.testing.assert_array_equal(np.sort(perm), np.arange(len(pts)))
    idx, has = inference._first_in_order(balls, perm, 16)
    ref_idx, ref_has = grouping.ball_query(pts[perm], centers, 2.0, 16)
    np.testing.assert_array_equal(has, np.asarray(ref_has))
    np.testing.assert_array_equal(idx[has], perm[np.asarray(ref_idx)[has]])
    assert not has[-1] and has[:-1].all()
    small = [len(b) for b in balls[:-1]]
    assert min(small) < 16 < max(small)   # both padded and subsampled balls are covered


def test_non_max_suppression_hand_computed():
  pts = np.array([[0.0, 0, 0], [0.3, 0, 0], [0.6, 0, 0], [5.0, 0, 0], [10.0, 0, 0]])
  scores = np.array([1.0, 3.0, 2.0, 0.5, 0.01])
  # 1 beats its neighbours 0 and 2; 2's neighbour 1 is higher; 3 is alone;
  # 4 is alone but below 1 % of the maximum (0.03).
  np.testing.assert_array_equal(inference.non_max_suppression(pts, scores), [1, 3])
  np.testing.assert_array_equal(inference.non_max_suppression(pts, scores, max_keypoints=1), [1])


def test_detect_returns_strongest_isolated_points(model):
  pts = _cloud(np.random.default_rng(3), 2500)
  idx, att = inference.detect(model, pts, max_keypoints=50, chunk=512)
  assert 0 < len(idx) <= 50 and len(set(idx.tolist())) == len(idx)
  assert np.all(np.diff(att[idx]) <= 0)
  d = np.linalg.norm(pts[idx][:, None] - pts[idx][None], axis=-1) + np.eye(len(idx)) * 9
  assert d.min() > 0.5


def test_bad_clouds_are_refused(model):
  with pytest.raises(ValueError, match='cloud is empty'):
    inference.describe(model, np.zeros((0, 3)), np.zeros((1, 3)))
  bad = _cloud(np.random.default_rng(4), 100)
  bad[5] = np.nan
  with pytest.raises(ValueError, match='1 points have NaN/Inf'):
    inference.attention(model, bad)


@pytest.mark.slow
def test_load_restores_a_training_run(tiny_config, tmp_path):
  rng = np.random.default_rng(5)
  for i in range(3):
    np.save(tmp_path / f'{i}.npy', _cloud(rng, 1200))
  tiny_config.data.path = str(tmp_path)
  tiny_config.train.num_steps = 2
  state = train.train_and_evaluate(tiny_config, str(tmp_path / 'run'))
  loaded = inference.load(tmp_path / 'run')
  assert loaded.num_samples == tiny_config.model.num_samples
  direct = inference.Model.from_config(tiny_config, {'params': state.params,
                                                     'batch_stats': state.batch_stats})
  pts = _cloud(rng, 1500)
  np.testing.assert_array_equal(inference.describe(loaded, pts, pts[:20]),
                                inference.describe(direct, pts, pts[:20]))
  with pytest.raises(FileNotFoundError, match='no such checkpoint directory'):
    inference.load(tmp_path / 'nothing')


def test_descriptors_averaged_over_draws(model):
  rng = np.random.default_rng(7)
  pts = _cloud(rng, 4000)
  kp = pts[:40]
  single = inference.describe(model, pts, kp)
  # Draw 0 is the single-sampling order; more draws average other samplings of each ball.
  draws = [inference.describe(model, pts, kp, seed=s) for s in (0, (0, 1), (0, 2))]
  averaged = inference.describe(dataclasses.replace(model, draws=3), pts, kp)
  mean = np.sum(draws, axis=0)
  np.testing.assert_allclose(averaged, mean / np.linalg.norm(mean, axis=1, keepdims=True),
                             atol=1e-5)
  np.testing.assert_allclose(np.linalg.norm(averaged, axis=1), 1.0, atol=1e-5)
  assert float(np.abs(averaged - single).max()) > 1e-3        # the draws differ
  np.testing.assert_array_equal(averaged,
                                inference.describe(dataclasses.replace(model, draws=3), pts, kp))
  with pytest.raises(ValueError, match='draws must be >= 1'):
    inference.describe(dataclasses.replace(model, draws=0), pts, kp)


def test_restored_weights_must_fit_the_configured_network():
  config = paper_small.get_config()
  template = network.variables_template(config.model)
  variables = jax.tree.map(lambda s: np.zeros(s.shape, s.dtype), template)
  kept = inference.check_variables({**variables, 'opt_state': 1}, config.model, 'run/7')
  assert jax.tree.structure(kept) == jax.tree.structure(variables)
  config.model.descriptor_dim = 64
  with pytest.raises(ValueError, match='run/7: not the weights of the network'):
    inference.check_variables(variables, config.model, 'run/7')


@pytest.mark.real_data
def test_one_draw_finds_the_clusters_of_every_ball_from_the_shuffled_clouds_prefix():
  """`_first_in_prefix` (one draw) gives `_first_in_order`'s clusters exactly, on a real
  scan (most balls served by the prefix) and on a sparse crop of it (every ball falls
  back to the whole cloud)."""
  scan = io.read_cloud(shared_path('example', 'kitti_00_001554.bin'))[:, :3].astype(np.float32)
  radius = np.nextafter(4.0, 0)
  for points in (scan, scan[::40]):
    centers = points[np.random.default_rng(0).choice(len(points), 300, replace=False)]
    perm = inference._permutation(len(points), 0)
    balls = [np.asarray(b, np.int64)
             for b in spatial.cKDTree(points).query_ball_point(centers, radius)]
    expected = inference._first_in_order(balls, perm, 64)
    found = inference._first_in_prefix(points, centers, radius, perm, 64)
    np.testing.assert_array_equal(found[0], expected[0])
    np.testing.assert_array_equal(found[1], expected[1])


def test_describe_fn_is_describe_in_pure_jax(model):
  """Without shuffling, the pure function on the points in `describe`'s own random order
  gives `describe`'s descriptors; with it, under jit and vmap over padded clouds, it
  traces once and padding changes nothing."""
  import chex  # pylint: disable=g-import-not-at-top
  rng = np.random.default_rng(3)
  pts = _cloud(rng, 3000)
  kp = pts[rng.choice(len(pts), 100, replace=False)]
  perm = inference._permutation(len(pts), 0)
  plain = inference.describe_fn(model, shuffle=False)
  np.testing.assert_allclose(np.asarray(jax.jit(plain)(pts[perm], kp)),
                             inference.describe(model, pts, kp), atol=2e-5)

  f = inference.describe_fn(model)
  batched = jax.jit(jax.vmap(chex.assert_max_traces(f, n=1)))
  other = _cloud(rng, 2500)
  clouds = np.zeros((2, 3000, 3), np.float32)
  clouds[0], clouds[1, :2500] = pts, other
  valid = np.arange(3000)[None] < np.array([[3000], [2500]])
  keypoints = np.stack([kp, other[:100]])
  keys = jax.random.split(jax.random.key(5), 2)
  out = np.asarray(batched(clouds, keypoints, valid, keys))
  assert out.shape == (2, 100, 32)
  np.testing.assert_allclose(np.linalg.norm(out, axis=-1), 1.0, atol=1e-5)
  alone = np.asarray(jax.jit(f)(other, other[:100], None, keys[1]))
  # A permutation of 2,500 real points and one of them padded to 3,000 differ, so the
  # clusters are other samples of the same balls: close, not equal.
  assert np.mean(np.sum(out[1] * alone, -1)) > 0.9
  batched(clouds + 1.0, keypoints + 1.0, valid, keys)   # new values, no new trace


def test_describe_fn_of_the_shipped_model_matches_a_scan_to_its_turned_copy():
  """jit(vmap(describe_fn(ours))) on a real scan and its copy turned about z matches the
  keypoints as `describe` does (its descriptors' nearest neighbours), each scan's balls
  sampled by its own draws."""
  from ssd_jax import pretrained  # pylint: disable=g-import-not-at-top
  from ssd_jax.registration import cloud_features  # pylint: disable=g-import-not-at-top
  from ssd_jax.registration import keypoints as keypoints_lib  # pylint: disable=g-import-not-at-top
  scan = io.read_cloud(shared_path('kitti_object_velodyne', '000000.bin'))
  points, _ = cloud_features.to_grid(scan.astype(np.float32), 0.2)
  model = pretrained.load('ours')
  kp = points[keypoints_lib.farthest_point_keypoints(points, 256)]
  angle = np.deg2rad(70.0)
  rot = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0],
                  [0, 0, 1]], np.float32)
  clouds, keypoints = np.stack([points, points @ rot.T]), np.stack([kp, kp @ rot.T])
  keys = jax.random.split(jax.random.key(0), 2)   # each scan its own samplings
  out = np.asarray(jax.jit(jax.vmap(inference.describe_fn(model)))(clouds, keypoints, None, keys))

  def matched(d1, d2):
    return np.mean(np.argmax(d1 @ d2.T, axis=1) == np.arange(len(d1)))

  ours = matched(out[0], out[1])
  host = matched(inference.describe(model, clouds[0], keypoints[0]),
                 inference.describe(model, clouds[1], keypoints[1], seed=1))
  assert ours > 0.5 and abs(ours - host) < 0.1, (ours, host)
