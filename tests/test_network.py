import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from ssd_jax import geometry, grouping, layers, network
from ssd_jax.evaluation import orientation


def _clusters_of(points, centers, radius=2.0, c=32):
  idx, has = grouping.ball_query(points, centers, radius, c)
  return grouping.group_points(points, centers, idx, has, radius)


@pytest.mark.slow
@pytest.mark.parametrize('dim', network.DESCRIPTOR_DIMS)
def test_feature_net_shapes_and_unit_descriptors(dim):
  clusters = jax.random.uniform(jax.random.key(0), (2, 8, 16, 3), minval=-1, maxval=1)
  model = network.FeatureNet(descriptor_dim=dim)
  variables = model.init(jax.random.key(1), clusters)
  desc, att, angle = model.apply(variables, clusters)
  assert desc.shape == (2, 8, dim) and att.shape == (2, 8) and angle.shape == (2, 8)
  np.testing.assert_allclose(jnp.linalg.norm(desc, axis=-1), 1.0, atol=1e-5)
  assert bool((att >= 0).all())
  hidden = variables['params']['descriptor']['point_mlp2']['Dense_0']['kernel'].shape[-1]
  assert hidden == (256 if dim > 64 else 128)


def test_bad_descriptor_dim_is_a_clear_error():
  with pytest.raises(ValueError, match='descriptor_dim must be one of'):
    network.FeatureNet(descriptor_dim=20).init(jax.random.key(0), jnp.zeros((1, 4, 8, 3)))


@pytest.mark.slow
def test_descriptors_invariant_to_z_rotation_with_shifted_orientation():
  rng = np.random.default_rng(0)
  cloud = jnp.asarray(rng.uniform(-6, 6, (1500, 3)) * np.array([1, 1, 0.3]), jnp.float32)
  centers = cloud[:32]
  model = network.FeatureNet(descriptor_dim=32)
  clusters = _clusters_of(cloud, centers)
  variables = model.init(jax.random.key(0), clusters)
  _, _, angle = model.apply(variables, clusters)

  theta = 0.7
  rot = geometry.rotation_z(jnp.float32(theta))
  clusters_rot = _clusters_of(cloud @ rot.T, centers @ rot.T)
  describe = lambda c, a: model.apply(variables, c, a, method=network.FeatureNet.describe)
  d_ref = describe(clusters, angle)
  d_rot = describe(clusters_rot, angle + theta)
  np.testing.assert_allclose(d_rot, d_ref, atol=2e-5)
  # ... and a rotated cloud with unshifted angles does change them (the test can fail).
  assert float(jnp.max(jnp.abs(describe(clusters_rot, angle) - d_ref))) > 1e-2


def test_descriptor_only_mode_has_no_detector():
  model = network.FeatureNet(use_orientation=False)
  variables = model.init(jax.random.key(0), jnp.zeros((1, 4, 8, 3)))
  assert set(variables['params']) == {'descriptor'}


def test_batch_norm_relu_matches_autodiff_of_textbook_formula():
  x = jax.random.normal(jax.random.key(0), (300, 8)) * 3 + 1
  scale = jax.random.uniform(jax.random.key(1), (8,), minval=0.5, maxval=2)
  bias = jax.random.normal(jax.random.key(2), (8,))
  ct = jax.random.normal(jax.random.key(3), (300, 8))

  def reference(x, scale, bias):
    mean, var = jnp.mean(x, 0), jnp.var(x, 0)
    return jax.nn.relu((x - mean) / jnp.sqrt(var + layers.BN_EPSILON) * scale + bias)

  fused = lambda *a: layers.batch_norm_relu(*a)[0]
  np.testing.assert_allclose(fused(x, scale, bias), reference(x, scale, bias), atol=1e-5)
  g_fused = jax.grad(lambda *a: jnp.sum(fused(*a) * ct), argnums=(0, 1, 2))(x, scale, bias)
  g_ref = jax.grad(lambda *a: jnp.sum(reference(*a) * ct), argnums=(0, 1, 2))(x, scale, bias)
  for a, b in zip(g_fused, g_ref):
    np.testing.assert_allclose(a, b, atol=1e-4, rtol=1e-4)
  _, mean, var = layers.batch_norm_relu(x, scale, bias)
  np.testing.assert_allclose(var, jnp.var(x, 0), rtol=1e-4)


@pytest.mark.slow
def test_running_statistics_are_updated_in_training_only():
  model = network.FeatureNet()
  clusters = jax.random.uniform(jax.random.key(0), (1, 8, 16, 3), minval=-1, maxval=1)
  variables = model.init(jax.random.key(1), clusters)
  _, mutated = model.apply(variables, clusters, train=True, mutable=['batch_stats'])
  before = variables['batch_stats']['descriptor']['point_mlp1']['BatchNormReLU_0']['mean']
  after = mutated['batch_stats']['descriptor']['point_mlp1']['BatchNormReLU_0']['mean']
  np.testing.assert_array_equal(before, 0.0)
  assert float(jnp.max(jnp.abs(after))) > 0
  d_eval, _, _ = model.apply({'params': variables['params'], **mutated}, clusters, train=False)
  assert bool(jnp.isfinite(d_eval).all())


def _oriented_clusters(rng, n):
  """[n, 32, 3] unit-ball clusters with a heading: a wall segment along x and a blob off
  to one side (no 180° symmetry), each turned by its own random angle."""
  wall = rng.uniform(-1, 1, (n, 32, 3)) * np.array([1.0, 0.15, 0.5])
  blob = rng.normal(0, 0.15, (n, 1, 3)) + np.array([0.5, 0.5, 0.0]) + rng.normal(0, 0.1, (n, 32, 3))
  points = np.where(rng.random((n, 32, 1)) < 0.3, blob, wall)
  return grouping.rotate_clusters(jnp.asarray(points, jnp.float32),
                                  jnp.asarray(rng.uniform(0, 2 * np.pi, n), jnp.float32))


@pytest.mark.slow
def test_detector_can_learn_to_turn_with_the_cluster():
  """The orientation head (atan2 of a learned 2-vector) can learn equivariance: supervised
  directly on theta(turned by phi) - theta = phi, the held-out error falls from chance
  (median ~90°) to well below it in a few hundred steps."""
  rng = np.random.default_rng(0)
  train_clusters, held_out = _oriented_clusters(rng, 1024), _oriented_clusters(rng, 256)
  detector = network.Detector()
  variables = detector.init(jax.random.key(0), train_clusters[:8], True)
  opt = optax.adam(1e-3)

  def turn_error(params, batch_stats, clusters, phi, train):
    turned = jnp.einsum('kji,kci->kcj', geometry.rotation_z(phi), clusters)  # Rz(phi) x
    both = jnp.concatenate([clusters, turned])
    (_, theta), new = detector.apply({'params': params, 'batch_stats': batch_stats}, both,
                                     train, mutable=['batch_stats'])
    before, after = jnp.split(theta, 2)
    return after - before - phi, new['batch_stats']

  @jax.jit
  def step(params, batch_stats, opt_state, key):
    k_idx, k_phi = jax.random.split(key)
    idx = jax.random.choice(k_idx, len(train_clusters), (64,), replace=False)
    phi = jax.random.uniform(k_phi, (64,), maxval=2 * jnp.pi)

    def loss(p):
      d, new_stats = turn_error(p, batch_stats, train_clusters[idx], phi, True)
      return jnp.mean(1 - jnp.cos(d)), new_stats
    (_, new_stats), grads = jax.value_and_grad(loss, has_aux=True)(params)
    updates, opt_state = opt.update(grads, opt_state, params)
    return optax.apply_updates(params, updates), new_stats, opt_state

  def median_error_deg(params, batch_stats):
    phi = jnp.asarray(np.random.default_rng(1).uniform(0, 2 * np.pi, len(held_out)), jnp.float32)
    d, _ = turn_error(params, batch_stats, held_out, phi, False)
    return float(np.median(orientation.orientation_error_deg(np.zeros_like(d), d, 0.0)))

  params, batch_stats = variables['params'], variables['batch_stats']
  opt_state = opt.init(params)
  before = median_error_deg(params, batch_stats)
  for i in range(300):
    params, batch_stats, opt_state = step(params, batch_stats, opt_state,
                                          jax.random.fold_in(jax.random.key(1), i))
  after = median_error_deg(params, batch_stats)
  assert before > 60, before
  assert after < 35, (before, after)


def _outputs_before_and_after_a_turn(head, theta):
  """FeatureNet(orientation_head=head) on 32 clusters of a random cloud, and on the same
  clusters of the cloud turned by theta about z -> ((desc, att, angle), (... turned))."""
  rng = np.random.default_rng(1)
  cloud = jnp.asarray(rng.uniform(-6, 6, (1500, 3)) * np.array([1, 1, 0.3]), jnp.float32)
  centers = cloud[:32]
  model = network.FeatureNet(orientation_head=head)
  clusters = _clusters_of(cloud, centers)
  variables = model.init(jax.random.key(0), clusters)
  rot = geometry.rotation_z(jnp.float32(theta))
  return (model.apply(variables, clusters),
          model.apply(variables, _clusters_of(cloud @ rot.T, centers @ rot.T)))


@pytest.mark.parametrize('theta', [0.5, 1.6, 2.9, -2.4, np.pi])
def test_equivariant_head_turns_with_the_cluster_all_the_way_round(theta):
  (desc, att, angle), (desc_r, att_r, angle_r) = _outputs_before_and_after_a_turn(
      'equivariant', theta)
  np.testing.assert_allclose(orientation.orientation_error_deg(angle, angle_r, theta), 0,
                             atol=1e-3)
  np.testing.assert_allclose(desc_r, desc, atol=5e-5)
  np.testing.assert_allclose(att_r, att, rtol=1e-5)


def test_paper_head_is_not_equivariant_by_construction():
  """The control: 3DFeat-Net's head, untrained, does not follow a half turn."""
  (desc, _, angle), (desc_r, _, angle_r) = _outputs_before_and_after_a_turn('mlp', np.pi)
  assert np.median(orientation.orientation_error_deg(angle, angle_r, np.pi)) > 10
  assert float(jnp.max(jnp.abs(desc_r - desc))) > 1e-2


def test_unknown_orientation_head_is_a_clear_error():
  with pytest.raises(ValueError, match='orientation_head must be one of'):
    network.FeatureNet(orientation_head='pca').init(jax.random.key(0), jnp.zeros((1, 4, 8, 3)))


def test_broadcast_dense_equals_dense_on_the_concatenation():
  rng = np.random.default_rng(0)
  x = jnp.asarray(rng.normal(size=(2, 3, 5, 4)), jnp.float32)     # [B, k, c, A]
  g = jnp.asarray(rng.normal(size=(2, 3, 6)), jnp.float32)        # [B, k, B']
  layer = layers.BroadcastDense(7)
  params = layer.init(jax.random.key(0), x, g)
  concat = jnp.concatenate([x, jnp.broadcast_to(g[..., None, :], (2, 3, 5, 6))], -1)
  dense = nn.Dense(7)
  # The same kernel shape and initialiser as nn.Dense on the concatenation, so stored
  # weights of either layout load into the other.
  ref_params = dense.init(jax.random.key(0), concat)
  assert jax.tree.map(jnp.shape, params) == jax.tree.map(jnp.shape, ref_params)
  np.testing.assert_array_equal(params['params']['kernel'], ref_params['params']['kernel'])
  params = jax.tree.map(lambda a: a + jnp.asarray(rng.normal(size=a.shape), a.dtype), params)
  np.testing.assert_allclose(layer.apply(params, x, g), dense.apply(params, concat),
                             rtol=1e-5, atol=1e-5)
