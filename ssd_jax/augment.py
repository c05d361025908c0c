"""Random self-rotation, jitter and branch resampling drawn with `jax.random`.

The paper's self-supervision (docs/method.md §2) rotates and jitters; the branch
resampling (point dropout, offset crops) is this project's label-free remedy for two
branches that are otherwise the same points.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import ml_collections

from ssd_jax import geometry


def self_rotate(key: jax.Array, points: jax.Array, sigma: float,
                clip: float | None, distribution: str = 'gaussian'
                ) -> tuple[jax.Array, jax.Array]:
  """PC2 = R_random PC1 with R_random about z by `self_rotation_angle`.

  points [B, N, 3] metres -> (rotated [B, N, 3], R_random [B, 3, 3]). The
  rotation is about the sensor origin, which is where the clouds are centred.
  """
  phi = self_rotation_angle(key, points.shape[:1], distribution, sigma, clip)
  rot = geometry.rotation_z(phi)
  return points @ jnp.swapaxes(rot, -1, -2), rot


SELF_ROTATIONS = ('gaussian', 'uniform')


def self_rotation_angle(key: jax.Array, shape: tuple[int, ...], distribution: str,
                        sigma: float, clip: float | None) -> jax.Array:
  """Self-rotation angles [*shape] radians: 'gaussian' N(0, sigma^2) clipped to +-clip
  (the paper), or 'uniform' over the whole circle [-pi, pi) (real scan pairs come at
  any relative yaw; the Gaussian almost never shows the network one beyond ~70 deg)."""
  if distribution == 'gaussian':
    return geometry.random_z_angle(key, shape, sigma, clip)
  if distribution == 'uniform':
    return jax.random.uniform(key, shape, minval=-jnp.pi, maxval=jnp.pi)
  raise ValueError(f'self-rotation must be one of {SELF_ROTATIONS}, got {distribution!r}')


def point_dropout(key: jax.Array, valid: jax.Array, max_rate: float) -> jax.Array:
  """Drop a random share of each cloud's points: valid [B, N] -> valid [B, N].

  Each cloud draws its rate uniformly in [0, max_rate], then each point is dropped
  with that probability. Applied to the two branches with their own keys, it makes
  them two different samplings of the same surfaces, at different densities.
  """
  k_rate, k_point = jax.random.split(key)
  rate = jax.random.uniform(k_rate, valid.shape[:1] + (1,), maxval=max_rate)
  return valid & (jax.random.uniform(k_point, valid.shape) >= rate)


def crop_around_offset(key: jax.Array, points: jax.Array, valid: jax.Array, shift: float,
                       radius: float) -> jax.Array:
  """Keep the points within `radius` metres (horizontally) of a point drawn uniformly in
  the disk of radius `shift` around the sensor: valid [B, N] -> valid [B, N].

  Two branches cropped around their own offsets overlap only partly, as two scans
  from a sensor that moved.
  """
  k_r, k_a = jax.random.split(key)
  b = points.shape[0]
  r = shift * jnp.sqrt(jax.random.uniform(k_r, (b,)))
  a = jax.random.uniform(k_a, (b,), minval=-jnp.pi, maxval=jnp.pi)
  center = jnp.stack([r * jnp.cos(a), r * jnp.sin(a)], -1)[:, None, :]
  return valid & (jnp.sum((points[..., :2] - center) ** 2, -1) <= radius ** 2)


def jitter(key: jax.Array, points: jax.Array, sigma: float, clip: float | None) -> jax.Array:
  """Per-point Gaussian noise N(0, sigma^2) metres, clipped to +-clip: [..., 3] -> [..., 3]."""
  noise = sigma * jax.random.normal(key, points.shape, points.dtype)
  if clip is not None:
    noise = jnp.clip(noise, -clip, clip)
  return points + noise


# 3DFeat-Net's augmentations (docs/method.md §5), one draw per cloud of a batch [B, N, 3].

def rotate_small(key: jax.Array, points: jax.Array, sigma: float = 0.06,
                 clip: float = 0.18) -> jax.Array:
  """RotateSmall: small rotations about x, y and z, each angle N(0, sigma^2) radians
  clipped to +-clip, about the sensor origin."""
  ang = jnp.clip(sigma * jax.random.normal(key, (points.shape[0], 3)), -clip, clip)
  c, s = jnp.cos(ang), jnp.sin(ang)
  one, zero = jnp.ones_like(c[:, 0]), jnp.zeros_like(c[:, 0])
  rx = jnp.stack([one, zero, zero, zero, c[:, 0], -s[:, 0], zero, s[:, 0], c[:, 0]], -1)
  ry = jnp.stack([c[:, 1], zero, s[:, 1], zero, one, zero, -s[:, 1], zero, c[:, 1]], -1)
  rot = rx.reshape(-1, 3, 3) @ ry.reshape(-1, 3, 3) @ geometry.rotation_z(ang[:, 2])
  return points @ jnp.swapaxes(rot, -1, -2)


def shift(key: jax.Array, points: jax.Array, max_shift: float = 0.1) -> jax.Array:
  """Shift: one uniform offset in [-max_shift, max_shift]^3 metres per cloud."""
  offset = jax.random.uniform(key, (points.shape[0], 1, 3), points.dtype, -max_shift, max_shift)
  return points + offset


def rotate_1d(key: jax.Array, points: jax.Array) -> jax.Array:
  """Rotate1D: a uniform random rotation about z per cloud."""
  phi = jax.random.uniform(key, points.shape[:1], points.dtype, -jnp.pi, jnp.pi)
  return points @ jnp.swapaxes(geometry.rotation_z(phi), -1, -2)


def _per_cloud_chance(key: jax.Array, b: int, rate: float) -> jax.Array:
  """[B, 1] bool: which clouds of a batch get an augmentation applied with chance `rate`."""
  return (jax.random.uniform(key, (b, 1)) < rate)


def beam_resample(key: jax.Array, points: jax.Array, valid: jax.Array, rate: float,
                  spacing: tuple[float, float], width: float = 0.2) -> jax.Array:
  """Re-sample a cloud to a sparser spinning LiDAR's beam pattern: valid [B, N] -> [B, N].

  With chance `rate` per cloud, draw a beam spacing uniformly in `spacing` (degrees of
  elevation between neighbouring beams, e.g. 2 for a VLP-16, 1.33 for an HDL-32E) and a
  random phase, and keep only the points within `width` degrees of a virtual beam. The
  elevation is seen from the sensor at the origin, where the clouds are centred, so a
  64-beam scan turns into rings as far apart as a 16- or 32-beam unit's.
  """
  k_on, k_s, k_phase = jax.random.split(key, 3)
  b = points.shape[0]
  s = jax.random.uniform(k_s, (b, 1), minval=spacing[0], maxval=spacing[1])
  phase = jax.random.uniform(k_phase, (b, 1))
  elev = jnp.degrees(jnp.arctan2(points[..., 2], jnp.linalg.norm(points[..., :2], axis=-1)))
  frac = jnp.mod(elev / s - phase, 1.0)
  near = jnp.minimum(frac, 1.0 - frac) * s <= width
  return valid & (near | ~_per_cloud_chance(k_on, b, rate))


def fov_crop(key: jax.Array, points: jax.Array, valid: jax.Array, rate: float,
             fov: tuple[float, float]) -> jax.Array:
  """A limited horizontal field of view (a front-facing or solid-state unit): with chance
  `rate` per cloud, keep the points within a sector of width drawn uniformly in `fov`
  degrees around a random heading. valid [B, N] -> [B, N]."""
  k_on, k_w, k_h = jax.random.split(key, 3)
  b = points.shape[0]
  half = 0.5 * jnp.radians(jax.random.uniform(k_w, (b, 1), minval=fov[0], maxval=fov[1]))
  heading = jax.random.uniform(k_h, (b, 1), minval=-jnp.pi, maxval=jnp.pi)
  az = jnp.arctan2(points[..., 1], points[..., 0]) - heading
  inside = jnp.abs(jnp.arctan2(jnp.sin(az), jnp.cos(az))) <= half
  return valid & (inside | ~_per_cloud_chance(k_on, b, rate))


# Fewer points than this in a branch after a simulated sensor change keep the branch as it
# was: a branch with a handful of clusters gives CF no rotation to recover.
MIN_BRANCH_POINTS = 512


def resample_branch(key: jax.Array, points: jax.Array, valid: jax.Array,
                    cfg: ml_collections.ConfigDict) -> jax.Array:
  """The points one branch keeps, valid [B, N] -> [B, N], so that the two branches differ
  as two scans of a place do:

    * `cfg.branch_dropout` (max share dropped) and `cfg.branch_crop_shift` /
      `cfg.branch_crop_radius` (metres; a crop around an offset sensor): another
      sampling, another standpoint;
    * `cfg.branch_sensor_rate` (chance per cloud) with `cfg.branch_beam_spacing`
      (degrees): another, sparser beam pattern (`beam_resample`);
    * `cfg.branch_fov_rate` with `cfg.branch_fov` (degrees): a limited horizontal field
      of view (`fov_crop`).

  A sensor change that would leave a cloud fewer than `MIN_BRANCH_POINTS` points is not
  applied to it. Points are given in the unrotated frame, so the crop of PC2 is drawn in
  PC1's frame: the same thing as a crop drawn after the rotation."""
  k_drop, k_crop, k_beam, k_fov = jax.random.split(key, 4)
  if cfg.branch_dropout > 0:
    valid = point_dropout(k_drop, valid, cfg.branch_dropout)
  if cfg.branch_crop_shift > 0:
    valid = crop_around_offset(k_crop, points, valid, cfg.branch_crop_shift,
                                       cfg.branch_crop_radius)
  sensor = valid
  if cfg.branch_sensor_rate > 0:
    sensor = beam_resample(k_beam, points, sensor, cfg.branch_sensor_rate,
                                   tuple(cfg.branch_beam_spacing))
  if cfg.branch_fov_rate > 0:
    sensor = fov_crop(k_fov, points, sensor, cfg.branch_fov_rate, tuple(cfg.branch_fov))
  enough = jnp.sum(sensor, axis=1, keepdims=True) >= MIN_BRANCH_POINTS
  return jnp.where(enough, sensor, valid)


def self_supervised_branches(key: jax.Array, points: jax.Array, valid: jax.Array,
                             cfg: ml_collections.ConfigDict):
  """The paper's two branches of a batch of unlabeled clouds (docs/method.md §2): PC1 the
  cloud, PC2 the cloud turned about z by R_gt (`self_rotate`), each jittered.

  points [B, N, 3] metres (valid [B, N]); or [B, 2, N, 3] (valid [B, 2, N]), each cloud
  beside a second view of it in its own frame (`datasets.RescanPairDataset`), which PC2
  turns instead of the cloud itself. Each branch may keep its own subset of the points
  (`resample_branch`; the paper: both keep all). The draws come from
  `jax.random.split(key, 5)[:3]` and `fold_in(key, 1)`: the loss draws its centres from
  the same split. -> (pc1 [B, N, 3], valid1 [B, N], pc2, valid2, r_gt [B, 3, 3])."""
  k_rot, k_jit1, k_jit2, _, _ = jax.random.split(key, 5)
  k_res1, k_res2 = jax.random.split(jax.random.fold_in(key, 1))
  if points.ndim == 4:
    view1, view2, seen1, seen2 = points[:, 0], points[:, 1], valid[:, 0], valid[:, 1]
  else:
    view1 = view2 = points
    seen1 = seen2 = valid
  pc2, r_gt = self_rotate(k_rot, view2, cfg.rotation_sigma, cfg.rotation_clip,
                          cfg.self_rotation)
  pc1 = jitter(k_jit1, view1, cfg.jitter_sigma, cfg.jitter_clip)
  pc2 = jitter(k_jit2, pc2, cfg.jitter_sigma, cfg.jitter_clip)
  return (pc1, resample_branch(k_res1, view1, seen1, cfg), pc2,
          resample_branch(k_res2, view2, seen2, cfg), r_gt)
