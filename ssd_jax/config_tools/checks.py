"""Checks of a training config: every value in range and consistent (`check_config`),
and whether a run stored in a workdir may continue under it (`check_resumable`). Each
failure is a `ConfigError` whose message names the field and the value."""

from __future__ import annotations

import json

import jax
import ml_collections

from ssd_jax import augment, grouping, inference, network, objective, sensors
from ssd_jax.config_tools import upgrade
from ssd_jax.infra import errors
from ssd_jax.data import datasets, rescan

AUGMENTATIONS = ('jitter', 'rotate_small', 'shift', 'rotate_1d')
LR_SCHEDULES = ('constant', 'cosine')


class ConfigError(errors.UserError):
  """A config value is out of range or inconsistent."""


def check_config(config: ml_collections.ConfigDict, num_devices: int | None = None) -> None:
  """Raise `ConfigError` naming the first bad value."""
  m, t, d = config.model, config.train, config.data

  def require(ok: bool, msg: str):
    if not ok:
      raise ConfigError(msg)

  def one_of(field: str, choices):
    section, _, key = field.rpartition('.')
    value = (config[section] if section else config).get(key)
    require(value in choices, f'{field} must be one of {tuple(choices)}, got {value!r}')

  one_of('objective', objective.OBJECTIVES)
  bad = set(m.augmentations) - set(AUGMENTATIONS)
  require(not bad, f'model.augmentations: unknown {sorted(bad)}; choose from {AUGMENTATIONS}')
  one_of('data.triplet_axes', datasets.TRIPLET_AXES)
  one_of('data.triplet_positives', datasets.TRIPLET_POSITIVES)
  require(m.margin >= 0, f'model.margin must be >= 0, got {m.margin}')
  one_of('model.triplet_hinge', objective.TRIPLET_HINGES)
  one_of('model.attention_normalization', objective.ATTENTION_NORMALIZATIONS)
  require(not (m.attention_in_cf and not m.use_orientation),
          'model.attention_in_cf needs model.use_orientation (the detector predicts attention)')
  one_of('model.descriptor_dim', network.DESCRIPTOR_DIMS)
  require(m.num_clusters >= 3, f'model.num_clusters must be >= 3, got {m.num_clusters}')
  require(m.num_samples >= 1, f'model.num_samples must be >= 1, got {m.num_samples}')
  require(m.radius > 0, f'model.radius must be > 0 metres, got {m.radius}')
  require(m.alpha > 0, f'model.alpha must be > 0, got {m.alpha}')
  one_of('model.loss', objective.ROTATION_LOSSES)
  one_of('model.center_sampling', grouping.SAMPLERS)
  require(m.rotation_sigma >= 0, f'model.rotation_sigma must be >= 0, got {m.rotation_sigma}')
  one_of('model.self_rotation', augment.SELF_ROTATIONS)
  one_of('model.orientation_head', network.ORIENTATION_HEADS)
  require(0 <= m.branch_dropout <= 0.9,
          f'model.branch_dropout must be in [0, 0.9], got {m.branch_dropout}')
  require(m.branch_crop_shift >= 0,
          f'model.branch_crop_shift must be >= 0 metres, got {m.branch_crop_shift}')
  require(m.branch_crop_radius > 0,
          f'model.branch_crop_radius must be > 0 metres, got {m.branch_crop_radius}')
  for rate in ('branch_sensor_rate', 'branch_fov_rate'):
    require(0 <= m[rate] <= 1, f'model.{rate} must be in [0, 1], got {m[rate]}')
  for field, lo in (('branch_beam_spacing', 0.0), ('branch_fov', 0.0)):
    span = tuple(m[field])
    require(len(span) == 2 and lo < span[0] <= span[1],
            f'model.{field} must be (low, high) degrees with 0 < low <= high, got {span}')
  require(m.branch_fov[1] <= 360, f'model.branch_fov must be within 360 degrees, got '
          f'{tuple(m.branch_fov)}')
  if d.rescan_rate > 0:
    require(d.rescan_rate <= 1, f'data.rescan_rate must be in [0, 1], got {d.rescan_rate}')
    bad = set(d.rescan_sensors) - set(sensors.SENSORS)
    require(d.rescan_sensors and not bad, f'data.rescan_sensors: unknown {sorted(bad)} (or '
            f'none given); choose from {tuple(sensors.SENSORS)}')
    span = tuple(d.rescan_shift)
    require(len(span) == 2 and 0 <= span[0] <= span[1],
            f'data.rescan_shift must be (low, high) metres with 0 <= low <= high, got {span}')
    require(d.rescan_views >= 1, f'data.rescan_views must be >= 1, got {d.rescan_views}')
    require(d.rescan_beams in rescan.BEAMS,
            f'data.rescan_beams must be one of {rescan.BEAMS}, got {d.rescan_beams!r}')
    require(config.objective == 'self_supervised',
            f'data.rescan_rate is for the self-supervised objective, not {config.objective!r}')
  if d.get('pairs'):
    require(0 < d.pairs_rate <= 1, f'data.pairs_rate must be in (0, 1], got {d.pairs_rate}')
    require(d.rescan_rate == 0, 'data.pairs and data.rescan_rate are two different second '
            'views: set one of them')
    require(config.objective == 'self_supervised',
            f'data.pairs is for the self-supervised objective, not {config.objective!r}')
    require(d.pairs_weight in datasets.PAIR_WEIGHTS,
            f'data.pairs_weight must be one of {datasets.PAIR_WEIGHTS}, got {d.pairs_weight!r}')
    require(isinstance(d.pairs_links, int) and d.pairs_links >= 1,
            f'data.pairs_links must be a whole number >= 1, got {d.pairs_links!r}')
  require(m.jitter_sigma >= 0, f'model.jitter_sigma must be >= 0, got {m.jitter_sigma}')
  require(m.contrastive_weight >= 0,
          f'model.contrastive_weight must be >= 0, got {m.contrastive_weight}')
  require(m.contrastive_rows in objective.CONTRASTIVE_ROWS,
          f'model.contrastive_rows must be one of {objective.CONTRASTIVE_ROWS}, got '
          f'{m.contrastive_rows!r}')
  require(m.contrastive_radius > 0 and m.contrastive_temperature > 0,
          'model.contrastive_radius and contrastive_temperature must be > 0, got '
          f'{m.contrastive_radius} and {m.contrastive_temperature}')
  require(isinstance(m.partner_centers, bool),
          f'model.partner_centers must be True or False, got {m.partner_centers!r}')
  require(isinstance(m.partner_jitter, (int, float)) and m.partner_jitter >= 0,
          f'model.partner_jitter must be a distance >= 0 (metres), got {m.partner_jitter!r}')
  require(m.partner_jitter == 0 or m.partner_centers,
          'model.partner_jitter moves partner centres: it needs model.partner_centers')
  require(d.num_points >= m.num_clusters,
          f'data.num_points ({d.num_points}) must be >= model.num_clusters ({m.num_clusters}): '
          'every cluster center is one of the input points')
  require(config.inference.num_samples >= 0,
          f'inference.num_samples must be >= 0 (0: model.num_samples), '
          f'got {config.inference.num_samples}')
  require(config.inference.draws >= 1,
          f'inference.draws must be >= 1, got {config.inference.draws}')
  require(config.inference.voxel_size >= 0,
          f'inference.voxel_size must be >= 0 metres, got {config.inference.voxel_size}')
  require(config.inference.keypoints in inference.KEYPOINT_SELECTIONS,
          f'inference.keypoints must be one of {inference.KEYPOINT_SELECTIONS}, got '
          f'{config.inference.keypoints!r}')
  require(t.batch_size >= 1, f'train.batch_size must be >= 1, got {t.batch_size}')
  require(t.learning_rate > 0, f'train.learning_rate must be > 0, got {t.learning_rate}')
  require(t.lr_schedule in LR_SCHEDULES,
          f'train.lr_schedule must be one of {LR_SCHEDULES}, got {t.lr_schedule!r}')
  require(t.init_scope in ('descriptor', 'model'),
          f"train.init_scope must be 'descriptor' or 'model', got {t.init_scope!r}")
  require(t.num_steps >= 1, f'train.num_steps must be >= 1, got {t.num_steps}')
  require(t.log_every >= 1 and t.checkpoint_every >= 1 and t.eval_every >= 1,
          'train.log_every, train.eval_every and train.checkpoint_every must be >= 1')
  n = jax.device_count() if num_devices is None else num_devices
  require(t.batch_size % n == 0,
          f'train.batch_size ({t.batch_size}) must be divisible by the {n} devices of the '
          f'run ({jax.process_count()} process(es); the batch is split across them)')


TRIPLET_ONLY_KEYS = ('triplet_hinge', 'attention_normalization')


def check_resumable(config: ml_collections.ConfigDict, stored: dict, directory: str) -> None:
  """Refuse to continue a checkpoint written with a different model or seed."""
  current = json.loads(json.dumps(config.to_dict()))   # tuples -> lists, as stored
  upgraded = upgrade.upgrade(stored).to_dict()
  for section in ('model',):
    for key, value in current[section].items():
      if (key in TRIPLET_ONLY_KEYS and key not in stored.get(section, {})
          and stored.get('objective') != 'triplet'):
        continue   # a triplet-only setting that the stored run never used
      was = upgraded.get(section, {}).get(key)
      if was != value:
        raise ConfigError(
            f'{directory} holds a run with {section}.{key}={was!r}, '
            f'but the config says {value!r}; use a new --workdir or the same config')
  if stored.get('seed') != config.seed:
    raise ConfigError(f'{directory} holds a run with seed={stored.get("seed")}, but the config '
                      f'says {config.seed}; use a new --workdir or the same seed')
