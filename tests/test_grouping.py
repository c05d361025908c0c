import jax
import jax.numpy as jnp
import numpy as np

from ssd_jax import geometry, grouping


def ball_query_reference(points, centers, radius, c, valid):
  """Brute force PointNet++ semantics in numpy."""
  idx = np.zeros((len(centers), c), np.int32)
  has = np.zeros(len(centers), bool)
  for i, ctr in enumerate(centers):
    d2 = np.sum((ctr[None] - points) ** 2, -1)
    found = [j for j in range(len(points)) if valid[j] and d2[j] < radius * radius][:c]
    if found:
      has[i] = True
      idx[i] = found + [found[0]] * (c - len(found))
  return idx, has


def _cloud(seed, n):
  rng = np.random.default_rng(seed)
  return rng.uniform(-3, 3, (n, 3)).astype(np.float32)


def test_ball_query_matches_brute_force():
  for seed in range(3):
    pts = _cloud(seed, 300)
    centers = np.concatenate([pts[:20], np.array([[50.0, 50, 50]], np.float32)])  # last: empty
    valid = np.random.default_rng(seed + 10).random(300) > 0.2
    for radius, c in [(1.0, 8), (0.6, 32)]:  # 32 slots at r=0.6 leaves most clusters short
      idx, has = grouping.ball_query(jnp.asarray(pts), jnp.asarray(centers), radius, c,
                                     jnp.asarray(valid))
      ref_idx, ref_has = ball_query_reference(pts, centers, radius, c, valid)
      np.testing.assert_array_equal(has, ref_has)
      np.testing.assert_array_equal(idx, ref_idx)
      assert (~ref_has).any() and (ref_idx[ref_has][:, -1] == ref_idx[ref_has][:, 0]).any()


def test_ball_query_fully_masked_input():
  pts = _cloud(0, 50)
  idx, has = grouping.ball_query(jnp.asarray(pts), jnp.asarray(pts[:5]), 10.0, 4,
                                 jnp.zeros(50, bool))
  assert not np.asarray(has).any()
  np.testing.assert_array_equal(idx, 0)
  grouped = grouping.group_points(jnp.asarray(pts), jnp.asarray(pts[:5]), idx, has, 10.0)
  np.testing.assert_array_equal(grouped, 0.0)


def test_group_points_is_normalised_by_radius():
  pts = _cloud(1, 200)
  idx, has = grouping.ball_query(jnp.asarray(pts), jnp.asarray(pts[:10]), 2.0, 16)
  grouped = np.asarray(grouping.group_points(jnp.asarray(pts), jnp.asarray(pts[:10]), idx, has, 2.0))
  assert grouped.shape == (10, 16, 3)
  assert np.linalg.norm(grouped, axis=-1).max() < 1.0
  np.testing.assert_allclose(grouped[0, 0], (pts[idx[0, 0]] - pts[0]) / 2.0, atol=1e-6)


def farthest_point_reference(points, k, start):
  idx = [start]
  dist = np.sum((points - points[start]) ** 2, -1)
  for _ in range(k - 1):
    idx.append(int(np.argmax(dist)))
    dist = np.minimum(dist, np.sum((points - points[idx[-1]]) ** 2, -1))
  return np.array(idx)


def test_farthest_point_sample_matches_reference_and_skips_invalid():
  pts = _cloud(2, 400)
  np.testing.assert_array_equal(grouping.farthest_point_sample(jnp.asarray(pts), 32),
                                farthest_point_reference(pts, 32, 0))
  valid = np.ones(400, bool)
  valid[::3] = False
  idx = np.asarray(grouping.farthest_point_sample(jnp.asarray(pts), 64, jnp.asarray(valid), 0))
  assert valid[idx].all() and len(set(idx.tolist())) == 64  # start 0 invalid -> first valid


def test_fewer_valid_points_than_centers_repeats_centers():
  pts = _cloud(3, 100)
  valid = np.zeros(100, bool)
  valid[:5] = True
  idx = np.asarray(grouping.farthest_point_sample(jnp.asarray(pts), 16, jnp.asarray(valid)))
  assert set(idx.tolist()) == set(range(5))
  ridx = grouping.random_sample(jax.random.key(0), 16, jnp.asarray(valid))
  assert valid[np.asarray(ridx)].sum() == 5


def test_sample_centers_batch_shapes_and_modes():
  pts = jnp.asarray(np.stack([_cloud(4, 128), _cloud(5, 128)]))
  valid = jnp.ones((2, 128), bool)
  for method in grouping.SAMPLERS:
    idx, cvalid = grouping.sample_centers(jax.random.key(0), pts, valid, 16, method)
    assert idx.shape == (2, 16) and bool(cvalid.all())
    assert all(len(set(np.asarray(row).tolist())) == 16 for row in idx)


def test_rotate_clusters_undoes_orientation():
  grouped = jnp.asarray(_cloud(6, 40).reshape(2, 4, 5, 3))
  angles = jnp.asarray(np.random.default_rng(0).uniform(-3, 3, (2, 4)), jnp.float32)
  turned = jnp.einsum('bkci,bkji->bkcj', grouped, geometry.rotation_z(angles))
  np.testing.assert_allclose(grouping.rotate_clusters(turned, angles), grouped, atol=1e-5)


def test_running_count_equals_cumsum_for_any_length():
  rng = np.random.default_rng(7)
  for n in (1, 63, 64, 100, 4096):
    mask = rng.random((3, 5, n)) < 0.3
    np.testing.assert_array_equal(grouping.running_count(jnp.asarray(mask)), np.cumsum(mask, -1))


def test_squared_distances_match_numpy_bitwise():
  a, b = _cloud(8, 40), _cloud(9, 70)
  np.testing.assert_array_equal(grouping.squared_distances(jnp.asarray(a), jnp.asarray(b)),
                                np.sum((a[:, None] - b[None]) ** 2, -1))
