import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ssd_jax import cf, geometry, objective, train


def _unit(x):
  return x / np.linalg.norm(x, axis=-1, keepdims=True)


def _known_problem(seed=0, k=512, d=32):
  rng = np.random.default_rng(seed)
  p = rng.uniform(-20, 20, (k, 3)).astype(np.float32)
  r = np.asarray(geometry.random_so3(jax.random.key(seed)))
  t = np.array([3.0, -1.5, 0.7], np.float32)
  perm = rng.permutation(k)
  q = (p @ r.T + t)[perm]
  f = _unit(rng.normal(size=(k, d))).astype(np.float32)
  return p, q, f, f[perm], r, t


def test_cf_recovers_known_transform_among_all_pairs():
  p, q, fp, fq, r, t = _known_problem()
  # alpha 0.01: every wrong pair weighs < exp(-50) of a true pair (random 32-D unit vectors).
  r_est, t_est = jax.jit(cf.cf_solve, static_argnums=4)(p, q, fp, fq, 0.01)
  np.testing.assert_allclose(r_est, r, atol=2e-5)
  np.testing.assert_allclose(t_est, t, atol=2e-4)


def test_cf_is_reflection_safe():
  # Points on a plane z = 0 mirrored through it: the best orthogonal fit of
  # mirrored 3-D data is a reflection; cf must still return a rotation.
  rng = np.random.default_rng(1)
  p = rng.normal(size=(50, 3)).astype(np.float32)
  q = p * np.array([1, 1, -1], np.float32)
  f = _unit(rng.normal(size=(50, 16))).astype(np.float32)
  r_est, _ = cf.cf_solve(p, q, f, f, 0.01)
  assert float(jnp.linalg.det(r_est)) == pytest.approx(1.0, abs=1e-5)
  np.testing.assert_allclose(r_est @ r_est.T, np.eye(3), atol=1e-5)


def test_cf_gradient_matches_finite_differences():
  rng = np.random.default_rng(2)
  k = 24
  p = rng.uniform(-5, 5, (k, 3))
  r_gt = np.asarray(geometry.random_so3(jax.random.key(5)), np.float64)
  q = p @ r_gt.T + 0.3 * rng.normal(size=(k, 3))
  fp = _unit(rng.normal(size=(k, 8)))
  fq = _unit(fp + 0.3 * rng.normal(size=(k, 8)))
  with jax.enable_x64(True):
    args = [jnp.asarray(a, jnp.float64) for a in (p, q, fp, fq, r_gt)]

    def loss(fp, fq):
      r, t = cf.cf_solve(args[0], args[1], fp, fq, 0.5)
      return objective.rotation_loss(r, args[4]) + 0.1 * jnp.sum(t ** 2)

    grads = jax.grad(loss, argnums=(0, 1))(args[2], args[3])
    eps = 1e-6
    for which in (0, 1):
      for (i, j) in [(0, 0), (5, 3), (k - 1, 7)]:
        plus, minus = [list(args[2:4]), list(args[2:4])]
        plus[which] = plus[which].at[i, j].add(eps)
        minus[which] = minus[which].at[i, j].add(-eps)
        fd = (loss(*plus) - loss(*minus)) / (2 * eps)
        assert float(grads[which][i, j]) == pytest.approx(float(fd), rel=1e-4, abs=1e-8)


@pytest.mark.parametrize('geometry_kind', ['planar', 'collinear', 'coincident', 'symmetric'])
def test_cf_gradients_finite_on_degenerate_geometry(geometry_kind):
  rng = np.random.default_rng(3)
  k = 64
  base = rng.normal(size=(k, 3)).astype(np.float32)
  if geometry_kind == 'planar':
    p = base * np.array([5, 5, 0], np.float32)
  elif geometry_kind == 'collinear':
    p = np.outer(rng.normal(size=k), [1.0, 2.0, 0.5]).astype(np.float32)
  elif geometry_kind == 'coincident':
    p = np.ones((k, 3), np.float32)
  else:  # equal singular values: points on the corners of a cube
    p = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)] * 8, np.float32)
  r_gt = geometry.rotation_z(jnp.float32(0.4))
  q = p @ np.asarray(r_gt).T
  feats = jnp.asarray(_unit(rng.normal(size=(k, 32))), jnp.float32)

  def loss(fp, fq):
    r, t = cf.cf_solve(p, q, fp, fq, 1.0)
    return objective.rotation_loss(r, r_gt) + jnp.sum(t)

  value, grads = jax.value_and_grad(loss, argnums=(0, 1))(feats, feats + 0.01)
  assert np.isfinite(float(value))
  assert all(np.isfinite(np.asarray(g)).all() for g in grads)


def test_cf_masks_exclude_clusters():
  p, q, fp, fq, r, t = _known_problem(k=64)
  q_bad = q.copy()
  mask_q = np.ones(64, bool)
  mask_q[:10] = False
  q_bad[:10] = 1e3  # garbage where masked
  r_est, t_est = cf.cf_solve(p, q_bad, fp, fq, 0.01, None, jnp.asarray(mask_q))
  np.testing.assert_allclose(r_est, r, atol=1e-4)
  r_none, t_none = cf.cf_solve(p, q, fp, fq, 1.0, jnp.zeros(64, bool), None)
  assert np.isfinite(np.asarray(r_none)).all() and np.isfinite(np.asarray(t_none)).all()


def test_cf_weights_do_not_underflow_for_small_alpha():
  rng = np.random.default_rng(4)
  f = _unit(rng.normal(size=(8, 4))).astype(np.float32)
  w = cf.descriptor_weights(f, -f, 1e-4)  # every pair far apart
  assert float(jnp.sum(w)) == pytest.approx(1.0, abs=1e-5) and bool(jnp.isfinite(w).all())


def test_rotation_loss_values_and_gradient_at_identity():
  theta = 0.3
  r = geometry.rotation_z(jnp.float32(theta))
  assert float(objective.rotation_loss(r, jnp.eye(3))) == pytest.approx(
      2 * np.sqrt(1 - np.cos(theta)), rel=1e-5)
  assert float(objective.rotation_loss(r, jnp.eye(3), 'squared_frobenius')) == pytest.approx(
      4 * (1 - np.cos(theta)), rel=1e-4)
  g = jax.grad(lambda a: objective.rotation_loss(geometry.rotation_z(a), jnp.eye(3)))(0.0)
  assert np.isfinite(float(g))
  with pytest.raises(ValueError, match='rotation loss must be one of'):
    objective.rotation_loss(r, r, 'l1')


def test_correspondence_nce_rewards_partners_alike_and_stays_finite_without_them():
  rng = np.random.default_rng(0)
  centers = jnp.asarray(rng.uniform(-20, 20, (64, 3)), jnp.float32)
  desc = rng.normal(size=(64, 16))
  desc = jnp.asarray(desc / np.linalg.norm(desc, axis=1, keepdims=True), jnp.float32)
  mask = jnp.ones(64, bool)
  nce = lambda c2, d2, m2=mask: objective.correspondence_nce(centers, c2, desc, d2, mask, m2,
                                                             1.0, 0.1)
  alike = float(nce(centers, desc))
  shuffled = float(nce(centers, desc[::-1]))
  assert alike < 0.1 < 2.0 < shuffled                  # log 64 = 4.2 for a blind guess
  # No centre of PC2 within the radius (or none valid): 0, and finite gradients.
  far = centers + 100.0
  assert float(nce(far, desc)) == 0.0
  for c2, m2 in ((far, mask), (centers, jnp.zeros(64, bool))):
    grad = jax.grad(lambda d: nce(c2, d, m2))(desc)
    assert np.isfinite(np.asarray(grad)).all()


def test_partner_centres_are_pc2s_points_nearest_pc1s_turned_centres():
  rng = np.random.default_rng(1)
  view = rng.uniform(-10, 10, (1, 200, 3)).astype(np.float32)
  phi = 1.1
  r_gt = np.array([[[np.cos(phi), -np.sin(phi), 0], [np.sin(phi), np.cos(phi), 0], [0, 0, 1]]],
                  np.float32)
  pc2 = view @ r_gt[0].T                        # PC2 is the view turned: rows p R_gt^T
  order = rng.permutation(200)                  # in its own point order
  pc2 = pc2[:, order]
  valid2 = np.ones((1, 200), bool)
  centres = view[:, :8]
  idx = np.asarray(objective.partner_indices(jnp.asarray(centres), jnp.asarray(pc2),
                                             jnp.asarray(valid2), jnp.asarray(r_gt)))
  np.testing.assert_array_equal(order[idx[0]], np.arange(8))
  # An invalid point is never a partner, even the one that would be exact.
  valid2[0, idx[0, 0]] = False
  idx = np.asarray(objective.partner_indices(jnp.asarray(centres), jnp.asarray(pc2),
                                             jnp.asarray(valid2), jnp.asarray(r_gt)))
  assert valid2[0, idx[0]].all() and order[idx[0, 0]] != 0


def test_jittered_partners_lie_within_the_jitter_of_the_exact_ones_and_are_seeded():
  rng = np.random.default_rng(2)
  # A dense, flat grid at 0.1 m: a partner's distance from its centre is the jitter's draw.
  g = np.stack(np.meshgrid(np.arange(-10, 10, 0.1), np.arange(-10, 10, 0.1)), -1).reshape(-1, 2)
  pc2 = jnp.asarray(np.concatenate([g, np.zeros((len(g), 1))], 1)[None], jnp.float32)
  valid2 = jnp.ones(pc2.shape[:2], bool)
  centres = jnp.asarray(np.concatenate([rng.uniform(-5, 5, (1, 256, 2)), np.zeros((1, 256, 1))],
                                       -1), jnp.float32)
  eye = jnp.eye(3)[None]
  gap = lambda idx: np.linalg.norm(np.asarray(pc2[0, idx[0]] - centres[0]), axis=1)
  jittered = lambda seed: objective.partner_indices(centres, pc2, valid2, eye,
                                                    jax.random.key(seed), 1.5)
  exact = gap(objective.partner_indices(centres, pc2, valid2, eye))
  assert exact.max() < 0.08                                  # the grid's half diagonal
  far = gap(jittered(0))
  assert far.max() < 1.5 + 0.08 and np.median(far) > 0.8     # uniform in the disc: 1.06
  np.testing.assert_array_equal(np.asarray(jittered(0)), np.asarray(jittered(0)))
  assert (np.asarray(jittered(1)) != np.asarray(jittered(0))).mean() > 0.9
  with pytest.raises(ValueError, match='needs a PRNG key'):
    objective.partner_indices(centres, pc2, valid2, eye, jitter=1.5)


def test_two_view_rows_keep_the_infonce_off_the_papers_pair(tiny_config):
  tiny_config.model.partner_centers = True
  rng = np.random.default_rng(3)
  cloud = rng.uniform(-8, 8, (2, 512, 3)) * [1, 1, 0.25]
  other = cloud + rng.normal(0, 0.05, cloud.shape)        # another view of the same place
  state = train.create_train_state(tiny_config, jax.random.key(0))
  variables = {'params': state.params, 'batch_stats': state.batch_stats}

  def loss(second, weight, rows):
    cfg = tiny_config.model.copy_and_resolve_references()
    cfg.contrastive_weight, cfg.contrastive_rows = weight, rows
    pts = jnp.asarray(np.stack([cloud, second], 1), jnp.float32)
    return float(objective.self_supervised_loss(
        train.create_model(tiny_config), variables, jax.random.key(1), pts,
        jnp.ones(pts.shape[:3], bool), cfg)[0])

  papers = cloud.copy()                                    # each row its own points again
  rotation_only = loss(papers, 0.0, 'all')
  assert loss(papers, 1.0, 'all') > rotation_only + 0.1
  assert loss(papers, 1.0, 'two_view') == pytest.approx(rotation_only, abs=1e-6)
  # One row of each: 'two_view' counts the InfoNCE of the other view's row only, as the
  # mean over such rows; with a second view in every row it is 'all'.
  mixed = np.stack([papers[0], other[1]])
  assert loss(mixed, 1.0, 'two_view') != pytest.approx(loss(mixed, 1.0, 'all'), abs=1e-4)
  assert loss(mixed, 1.0, 'two_view') > loss(mixed, 0.0, 'all') + 0.1
  assert loss(other, 1.0, 'two_view') == pytest.approx(loss(other, 1.0, 'all'), abs=1e-6)
  # A batch of single clouds (no second view at all) is the paper's pair in every row.
  cfg = tiny_config.model.copy_and_resolve_references()
  cfg.contrastive_weight, cfg.contrastive_rows = 1.0, 'two_view'
  single = objective.self_supervised_loss(
      train.create_model(tiny_config), variables, jax.random.key(1),
      jnp.asarray(cloud, jnp.float32), jnp.ones(cloud.shape[:2], bool), cfg)[0]
  cfg.contrastive_weight = 0.0
  alone = objective.self_supervised_loss(
      train.create_model(tiny_config), variables, jax.random.key(1),
      jnp.asarray(cloud, jnp.float32), jnp.ones(cloud.shape[:2], bool), cfg)[0]
  assert float(single) == pytest.approx(float(alone), abs=1e-6)
