"""Inference: descriptors at keypoints and attention keypoints of whole clouds.

    model = inference.load(checkpoint_dir)                       # or inference.Model(...)
    desc = inference.describe(model, cloud, keypoint_xyz)         # [K, D], host-side
    f = inference.describe_fn(model)                              # the same, pure JAX:
    desc = jax.jit(jax.vmap(f))(clouds, keypoints, valid)         # [B, N, 3] -> [B, K, D]
    kp_idx, attention = inference.detect(model, cloud)            # 3DFeat-Net keypoints

The network runs jitted on clusters of a fixed chunk size (the last chunk is padded and its
outputs dropped). Each cluster's points are gathered on the host, so the network compiles
once whatever the cloud's and keypoint set's size. Neighbourhoods are PointNet++ ball
queries (the first c points within r in index order, padded by repeating the first), found
by a host KD-tree (scipy), far faster on CPU for large clouds than `grouping.ball_query`'s
dense distances, which `describe_fn` uses inside JAX, with the same clusters (tested).
Clouds are put in a seeded random order first, so that "first c in index order" is a random
sample of the ball, as in training (`describe` finds each ball once and, for each draw,
keeps the members that come first in that draw's order).
"""

from __future__ import annotations

import dataclasses
import functools
import os
from typing import Any

import jax
import jax.numpy as jnp
import ml_collections
import numpy as np
from scipy import spatial

from ssd_jax import grouping, network
from ssd_jax.config_tools import upgrade
from ssd_jax.infra import errors
from ssd_jax.data.clean import check_cloud

# Where registration's default keypoints are sampled with a model (its config's
# `inference.keypoints`, `registration.pipeline.keypoint_domain`): the whole cloud, or the
# points above its ground.
KEYPOINT_SELECTIONS = ('all', 'structure')


@dataclasses.dataclass(frozen=True)
class Model:
  """A FeatureNet with its variables and grouping settings.

  Attributes:
    net: the Flax module.
    variables: {'params', 'batch_stats'}.
    radius: ball-query radius, metres.
    num_samples: points per cluster (c).
    step: the training step, for models restored by `load`.
    draws: `describe` averages the descriptors of this many random samplings of each
      ball (1: one sampling, as in training). A cluster holds c points drawn from the
      hundreds of points a ball holds in a 0.2 m-voxel scan, so one draw carries
      sampling noise that averaging removes, at `draws` times the network cost.
    voxel_size: the voxel grid (metres) of its training clouds, on which
      `registration.pipeline` puts every cloud before describing it.
    keypoints: `KEYPOINT_SELECTIONS`, what registration's 'auto' keypoints are sampled
      from: 'all' (the whole cloud) or 'structure' (the points above its ground;
      `experiments.adapt` picks it for a sensor unless all points register more of
      the mined pairs).
  """
  net: network.FeatureNet
  variables: Any
  radius: float = 2.0
  num_samples: int = 64
  step: int | None = None     # training step of a loaded checkpoint
  draws: int = 1
  voxel_size: float = 0.2     # metres: the grid of the clouds it was trained on
  keypoints: str = 'all'

  @classmethod
  def from_config(cls, config: ml_collections.ConfigDict, variables) -> 'Model':
    """The network of `config.model` with `variables`, describing as `config.inference`
    says (a stored config: after `upgrade.upgrade`)."""
    settings = config.inference
    if settings.keypoints not in KEYPOINT_SELECTIONS:
      raise errors.UserError(f'inference.keypoints must be one of {KEYPOINT_SELECTIONS}, got '
                             f'{settings.keypoints!r}')
    num_samples = int(settings.num_samples) or int(config.model.num_samples)
    return cls(network.create(config.model), variables, float(config.model.radius),
               num_samples, draws=int(settings.draws), voxel_size=float(settings.voxel_size),
               keypoints=str(settings.keypoints))


def checkpoint_directory(run_dir: str | os.PathLike) -> str:
  """A training run's `checkpoints/` folder (`run_dir` may already be it)."""
  directory = os.path.join(run_dir, 'checkpoints')
  if not os.path.isdir(directory):
    directory = str(run_dir)
  if not os.path.isdir(directory):
    raise FileNotFoundError(f'{run_dir}: no such checkpoint directory')
  return directory


def check_variables(variables, model_config, source: str) -> dict:
  """{'params', 'batch_stats'} of `variables` if their structure and shapes are those of
  `network.create(model_config)`, else a ValueError naming `source`."""
  template = network.variables_template(model_config)
  variables = {k: variables[k] for k in ('params', 'batch_stats') if k in variables}
  same = (jax.tree.structure(variables) == jax.tree.structure(template) and all(
      np.shape(a) == b.shape for a, b in zip(jax.tree.leaves(variables),
                                             jax.tree.leaves(template))))
  if not same:
    raise errors.UserError(f'{source}: not the weights of the network its config describes')
  return variables


def load(checkpoint_dir: str | os.PathLike, step: int | None = None) -> Model:
  """The model of a training run: `checkpoint_dir` is its workdir or its `checkpoints/`.
  Only params and BatchNorm statistics are read; a damaged checkpoint is a
  `checkpoint.CheckpointError` naming its folder."""
  # Only training runs need orbax, 0.2 s of a one-pair command's import time; shipped
  # and exported models (`pretrained`) load without it.
  from ssd_jax.infra import checkpoint  # pylint: disable=g-import-not-at-top
  directory = checkpoint_directory(checkpoint_dir)
  ckpt = checkpoint.Checkpointer(directory, asynchronous=False)
  if ckpt.latest_step() is None:
    raise FileNotFoundError(f'{directory}: holds no checkpoint')
  step = ckpt.latest_step() if step is None else step
  try:
    config = upgrade.upgrade(ckpt.restore_config(step))
    state, _ = ckpt.restore(None, step)   # as stored: no optimizer template needed
  finally:
    ckpt.close()
  variables = check_variables(state, config.model, f'{directory}/{step}')
  model = Model.from_config(config, variables)
  return dataclasses.replace(model, step=int(step))


# XLA:CPU hands dots, elementwise ops and reductions to YNNPACK one by one with this
# setting; its default groups the whole descriptor branch of a 256-cluster chunk into
# one library fusion that ran 1.4x slower on the 2-core VM (docs/notes/speed.md).
_CPU_COMPILER_OPTIONS = {'xla_cpu_experimental_ynn_fusion_type': ','.join(
    f'LIBRARY_FUSION_TYPE_{kind}' for kind in ('DOT', 'ELTWISE', 'REDUCE'))}


def _compiler_options() -> dict | None:
  """`_CPU_COMPILER_OPTIONS` on a CPU backend whose XLA knows them (the flag is
  experimental), else None."""
  if jax.default_backend() != 'cpu':
    return None
  try:
    jax.jit(jnp.negative, compiler_options=_CPU_COMPILER_OPTIONS).lower(
        np.zeros(1, np.float32)).compile()
  except Exception:  # pylint: disable=broad-except  (XLA reports an unknown option as it can)
    return None
  return _CPU_COMPILER_OPTIONS


def _run_on_groups(net, variables, points, centers, idx, has_nb, *, radius, what):
  clusters = grouping.group_points(points, centers, idx, has_nb, radius)
  if what == 'describe':
    return net.apply(variables, clusters, train=False)[0]
  return net.apply(variables, clusters, train=False, method=network.FeatureNet.detect)


@functools.lru_cache(maxsize=None)
def _network_kernel():
  """`_run_on_groups` jitted with `_compiler_options()` (decided once per process)."""
  return jax.jit(_run_on_groups, static_argnames=('net', 'radius', 'what'),
                 compiler_options=_compiler_options())


def describe_fn(model: Model, shuffle: bool = True):
  """`describe` as a pure JAX function, for use inside other JAX code.

  Returns f(points [N, 3], keypoints [K, 3], valid [N] bool = None, key = None) ->
  [K, D] float32, L2-normalised descriptors at the keypoints (metres; invalid rows of
  points, e.g. padding, are never grouped). Ball query, grouping, the network and the
  average over `model.draws` samplings all run in JAX with static shapes, so f works
  under `jax.jit`, `jax.vmap` (a batch of padded clouds) and `jax.lax` loops:

      f = inference.describe_fn(pretrained.load('ours'))
      desc = jax.jit(jax.vmap(f))(points, keypoints, valid)   # [B, N, 3], [B, K, 3], [B, N]

  A ball holds hundreds of points of a 0.2 m-voxel scan and a cluster c of them: with
  `shuffle` each draw takes the first c in a random order of the cloud drawn from `key`
  (default `jax.random.key(0)`; draw j uses `fold_in(key, j)`), a random sample of the
  ball as in training; without, the first c in the points' own order (`describe` of
  the same points in the order it draws with numpy, to the float rounding: tested).
  Memory is O(K N) (a dense ball query): chunk the keypoints of very large clouds.
  """
  def one_draw(points, keypoints, valid):
    idx, has = grouping.ball_query(points, keypoints, model.radius, model.num_samples, valid)
    clusters = grouping.group_points(points, keypoints, idx, has, model.radius)
    return model.net.apply(model.variables, clusters, train=False)[0]

  def describe_points(points: jax.Array, keypoints: jax.Array, valid: jax.Array | None = None,
                      key: jax.Array | None = None) -> jax.Array:
    points = jnp.asarray(points, jnp.float32)
    keypoints = jnp.asarray(keypoints, jnp.float32)
    valid = jnp.ones(points.shape[:1], bool) if valid is None else jnp.asarray(valid, bool)
    if not shuffle:
      return one_draw(points, keypoints, valid)
    key = jax.random.key(0) if key is None else key
    total = 0.0
    for draw in range(model.draws):
      order = jax.random.permutation(jax.random.fold_in(key, draw), points.shape[0])
      total = total + one_draw(points[order], keypoints, valid[order])
    if model.draws == 1:
      return total
    return total * jax.lax.rsqrt(jnp.sum(total * total, -1, keepdims=True) + 1e-24)

  return describe_points


def neighbourhoods(model: Model, points: np.ndarray, keypoints: np.ndarray,
                   seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
  """The clusters `describe` groups at keypoints [K, 3] in points [N, 3] (metres):
  idx [draws * K, c] point indices (draw-major), has_neighbour [draws * K] bool. They
  depend on the model's radius, num_samples and draws only, so models that share those
  share them (`describe(..., clusters=)`)."""
  points = check_cloud(points)
  keypoints = check_cloud(keypoints, 'keypoints')
  return _neighbourhoods(model, points, keypoints, _order_seeds(model.draws, seed))


def describe(model: Model, points: np.ndarray, keypoints: np.ndarray, chunk: int = 256,
             seed: int = 0,
             clusters: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
  """Learned descriptors at keypoints.

  points [N, 3] metres (the search surface); keypoints [K, 3] metres (cluster
  centers) -> [K, D] float32, L2-normalised (the normalised mean over `model.draws`
  samplings of each ball). The balls are found once; every draw is a different random
  subset of each, and the clusters of all draws go through the network together, in
  chunks of `chunk` (one compiled shape whatever the cloud's or keypoint set's size).
  clusters: `neighbourhoods(model, points, keypoints, seed)` where already found.
  """
  points = check_cloud(points)
  keypoints = check_cloud(keypoints, 'keypoints')
  order_seeds = _order_seeds(model.draws, seed)
  idx, has = (_neighbourhoods(model, points, keypoints, order_seeds)
              if clusters is None else clusters)
  centers = np.tile(keypoints, (len(order_seeds), 1))
  descriptors = _run_groups(model, points[idx], centers, has, chunk, 'describe')
  return _mean_over_draws(descriptors, len(order_seeds))


def _neighbourhoods(model: Model, points: np.ndarray, centers: np.ndarray,
                    order_seeds: list) -> tuple[np.ndarray, np.ndarray]:
  """The clusters at centers [K, 3] of every point order in `order_seeds` (draw-major),
  `grouping.ball_query`'s on the shuffled cloud found by a host KD-tree: idx [draws * K,
  c] original point indices, has_neighbour [draws * K] bool."""
  # cKDTree tests d <= r; ball_query tests d^2 < r^2. Shrinking r by one ulp makes the
  # boundary case agree.
  radius = np.nextafter(model.radius, 0)
  if len(order_seeds) == 1:
    idx, has = zip(_first_in_prefix(points, centers, radius,
                                    _permutation(len(points), order_seeds[0]),
                                    model.num_samples))
  else:   # the balls once, every draw's members from them
    balls = [np.asarray(b, np.int64)
             for b in spatial.cKDTree(points).query_ball_point(centers, radius)]
    idx, has = zip(*(_first_in_order(balls, _permutation(len(points), s), model.num_samples)
                     for s in order_seeds))
  return np.concatenate(idx), np.concatenate(has)


def _order_seeds(draws: int, seed) -> list:
  """The point orders of `draws` samplings: draw 0 is `seed`'s own order, so draws=1 is
  exactly the single-sampling result; draw j > 0 is (seed, j)."""
  if draws < 1:
    raise ValueError(f'model.draws must be >= 1, got {draws}')
  return [seed] + [(seed, draw) for draw in range(1, draws)]


def _permutation(n: int, order_seed) -> np.ndarray:
  """The seeded random order of n points (see the module docstring): new position -> old
  index."""
  return np.random.default_rng(order_seed).permutation(n)


def _first_in_order(balls: list[np.ndarray], perm: np.ndarray,
                    num_samples: int) -> tuple[np.ndarray, np.ndarray]:
  """The ball query on the shuffled cloud `points[perm]` (the first c members in that
  order, `grouping.ball_query`'s rule), from balls found once on the original.

  balls: K arrays of point indices within the radius; perm [N] as `_permutation` ->
  idx [K, c] int64 original indices (the c members that come first in the shuffled
  order, in that order, padded by repeating the first), has_neighbour [K] bool.
  """
  rank = np.empty_like(perm)
  rank[perm] = np.arange(len(perm))
  idx = np.zeros((len(balls), num_samples), np.int64)
  has = np.zeros(len(balls), bool)
  for k, ball in enumerate(balls):
    if not len(ball):
      continue
    r = rank[ball]
    if len(r) > num_samples:
      r = np.partition(r, num_samples - 1)[:num_samples]
    r.sort()
    idx[k, :len(r)] = perm[r]
    idx[k, len(r):] = perm[r[0]]
    has[k] = True
  return idx, has


# One draw: a ball's c members that come first in the draw's order are its c members of
# lowest rank, so a ball that holds c points of the first PREFIX share of the shuffled
# cloud has them there. A KD-tree of that prefix returns a quarter of the neighbours; the
# balls that hold fewer are queried on the whole cloud. The same clusters (tested).
PREFIX = 0.25


def _first_in_prefix(points: np.ndarray, centers: np.ndarray, radius: float,
                     perm: np.ndarray, num_samples: int) -> tuple[np.ndarray, np.ndarray]:
  """`_first_in_order` of the balls of `radius` at centers [K, 3] in points [N, 3] under
  the order perm [N], from the prefix of the shuffled cloud where it suffices."""
  prefix = max(int(len(points) * PREFIX), min(len(points), num_samples))
  # The prefix tree's indices are ranks in the draw's order; sorted, the first c come first.
  balls = spatial.cKDTree(points[perm[:prefix]]).query_ball_point(centers, radius,
                                                                  return_sorted=True)
  idx = np.zeros((len(centers), num_samples), np.int64)
  has = np.zeros(len(centers), bool)
  short = []
  for k, ball in enumerate(balls):
    if len(ball) >= num_samples:
      idx[k] = perm[ball[:num_samples]]
      has[k] = True
    else:
      short.append(k)
  if short:
    full = [np.asarray(b, np.int64)
            for b in spatial.cKDTree(points).query_ball_point(centers[short], radius)]
    idx[short], has[short] = _first_in_order(full, perm, num_samples)
  return idx, has


def _mean_over_draws(descriptors: np.ndarray, draws: int) -> np.ndarray:
  """descriptors [draws * K, D], draw-major -> [K, D]: the L2-normalised sum over draws
  (the one draw itself when draws=1)."""
  if draws == 1:
    return descriptors
  parts = np.split(descriptors, draws)
  total = parts[0]
  for part in parts[1:]:
    total = total + part
  return (total / np.linalg.norm(total, axis=1, keepdims=True).clip(1e-12)).astype(np.float32)


def _run_groups(model: Model, groups: np.ndarray, centers: np.ndarray, has: np.ndarray,
                chunk: int, what: str):
  """The network on host-gathered clusters, `chunk` at a time: groups [M, c, 3] metres,
  centers [M, 3], has [M] bool -> descriptors [M, D] ('describe') or (attention [M],
  orientation [M] radians) ('detect')."""
  c = model.num_samples
  # Each chunk is its own flat "cloud" of chunk * c points whose k-th cluster is rows
  # k*c ... k*c + c - 1, so the jitted network sees one static shape.
  flat_idx = jnp.arange(chunk * c, dtype=jnp.int32).reshape(chunk, c)
  run_network = _network_kernel()
  out = []
  for start in range(0, len(groups), chunk):
    m = min(chunk, len(groups) - start)
    pts = np.zeros((chunk, c, 3), np.float32)
    ctr = np.zeros((chunk, 3), np.float32)
    hb = np.zeros(chunk, bool)
    pts[:m], ctr[:m], hb[:m] = groups[start:start + m], centers[start:start + m], has[start:start + m]
    res = run_network(model.net, model.variables, jnp.asarray(pts.reshape(-1, 3)),
                      jnp.asarray(ctr), flat_idx, jnp.asarray(hb), radius=model.radius,
                      what=what)
    out.append(jax.tree.map(lambda a, m=m: np.asarray(a)[:m], res))
  if what == 'describe':
    return np.concatenate(out) if out else np.zeros((0, model.net.descriptor_dim), np.float32)
  if not out:
    return np.zeros(0, np.float32), np.zeros(0, np.float32)
  return np.concatenate([o[0] for o in out]), np.concatenate([o[1] for o in out])


def describe_clusters(model: Model, clouds, centers: np.ndarray | None = None, chunk: int = 256,
                      seed: int = 0) -> np.ndarray:
  """One learned descriptor per small cloud, at its center, batched across clouds.

  For descriptor-matching sets (docs/method.md §4) of thousands of cluster crops: equal to
  `describe(model, clouds[k], centers[k:k+1], seed=seed)` for every k, without a
  network call per crop. clouds: sequence of [N_k, 3] metres; centers [K, 3] metres
  (default: each crop's origin) -> [K, D] float32, averaged over `model.draws` samplings
  as `describe` does.
  """
  centers = (np.zeros((len(clouds), 3), np.float32) if centers is None
             else check_cloud(centers, 'centers'))
  if len(centers) != len(clouds):
    raise ValueError(f'{len(clouds)} clouds but {len(centers)} centers')
  clouds = [check_cloud(cloud, f'cloud {k}') for k, cloud in enumerate(clouds)]
  order_seeds = _order_seeds(model.draws, seed)
  c = model.num_samples
  groups = np.zeros((len(order_seeds), len(clouds), c, 3), np.float32)
  has = np.zeros((len(order_seeds), len(clouds)), bool)
  for k, cloud in enumerate(clouds):
    ball = [np.asarray(spatial.cKDTree(cloud).query_ball_point(
        centers[k], np.nextafter(model.radius, 0)), np.int64)]
    for d, order_seed in enumerate(order_seeds):
      idx, h = _first_in_order(ball, _permutation(len(cloud), order_seed), c)
      groups[d, k], has[d, k] = cloud[idx[0]], h[0]
  descriptors = _run_groups(model, groups.reshape(-1, c, 3),
                            np.tile(centers, (len(order_seeds), 1)), has.reshape(-1), chunk,
                            'describe')
  return _mean_over_draws(descriptors, len(order_seeds))


def detect_at(model: Model, points: np.ndarray, centers: np.ndarray, chunk: int = 2048,
              seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
  """The detector at given cluster centers: points [N, 3] metres (the search surface),
  centers [K, 3] metres -> attention [K] (>= 0) and orientation [K] (radians about z)."""
  if not model.net.use_orientation:
    raise ValueError('this model has no detector: it was trained with '
                     'model.use_orientation=False (3DFeat-Net\'s descriptor pre-training)')
  points = check_cloud(points)
  centers = check_cloud(centers, 'centers')
  idx, has = _neighbourhoods(model, points, centers, [seed])
  return _run_groups(model, points[idx], centers, has, chunk, 'detect')


def attention(model: Model, points: np.ndarray, chunk: int = 2048, seed: int = 0
              ) -> tuple[np.ndarray, np.ndarray]:
  """Attention [N] and orientation [N] (radians) with every point as a cluster center."""
  return detect_at(model, points, points, chunk, seed)


def non_max_suppression(points: np.ndarray, scores: np.ndarray, radius: float = 0.5,
                        min_ratio: float = 0.01, max_keypoints: int = 1024) -> np.ndarray:
  """3DFeat-Net keypoints (docs/method.md §4): points whose score is the highest within
  `radius` metres, at least `min_ratio` of the maximum, the strongest `max_keypoints`
  first. -> indices [K]."""
  pairs = spatial.cKDTree(points).query_pairs(radius, output_type='ndarray')
  best = scores.copy()
  if len(pairs):
    np.maximum.at(best, pairs[:, 0], scores[pairs[:, 1]])
    np.maximum.at(best, pairs[:, 1], scores[pairs[:, 0]])
  keep = np.flatnonzero((scores >= best) & (scores >= min_ratio * scores.max()))
  return keep[np.argsort(-scores[keep], kind='stable')][:max_keypoints]


def detect(model: Model, points: np.ndarray, nms_radius: float = 0.5, min_ratio: float = 0.01,
           max_keypoints: int = 1024, chunk: int = 2048) -> tuple[np.ndarray, np.ndarray]:
  """Attention keypoints: indices [K] into points (strongest first) and attention [N]."""
  att, _ = attention(model, points, chunk)
  return non_max_suppression(np.asarray(points, np.float32), att, nms_radius, min_ratio,
                             max_keypoints), att
