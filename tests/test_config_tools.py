"""ssd_jax.config_tools.checks: bad config values are named, and stored runs resume only under
the config they were trained with (old runs with the values they used)."""

import importlib.util
import json
from pathlib import Path

import ml_collections
import pytest

from ssd_jax.infra import cli
from ssd_jax.config_tools import checks, upgrade
from ssd_jax.configs.training import paper


def test_config_errors_name_the_value(tiny_config):
  cases = [('model.descriptor_dim', 20, 'descriptor_dim must be one of'),
           ('model.loss', 'l1', 'model.loss must be one of'),
           ('model.center_sampling', 'grid', 'center_sampling must be one of'),
           ('data.num_points', 32, r'data.num_points \(32\) must be >= model.num_clusters'),
           ('model.radius', 0.0, 'radius must be > 0'),
           ('model.triplet_hinge', 'anchor', "triplet_hinge must be one of .*'anchor'"),
           ('model.attention_normalization', 'max', 'attention_normalization must be one of'),
           ('model.self_rotation', 'vonmises', "self_rotation must be one of .*'vonmises'"),
           ('model.orientation_head', 'pca', 'orientation_head must be one of'),
           ('model.branch_dropout', 1.0, r'branch_dropout must be in \[0, 0.9\]'),
           ('model.branch_crop_shift', -1.0, 'branch_crop_shift must be >= 0'),
           ('model.branch_crop_radius', 0.0, 'branch_crop_radius must be > 0'),
           ('model.branch_sensor_rate', 1.5, r'branch_sensor_rate must be in \[0, 1\]'),
           ('model.branch_fov_rate', -0.1, r'branch_fov_rate must be in \[0, 1\]'),
           ('model.branch_beam_spacing', (2.0, 1.0), 'branch_beam_spacing must be'),
           ('model.branch_fov', (90.0, 400.0), 'branch_fov must be within 360'),
           ('inference.voxel_size', -0.2, 'inference.voxel_size must be >= 0 metres'),
           ('train.init_scope', 'detector', "init_scope must be 'descriptor' or 'model'"),
           ('train.lr_schedule', 'step', "lr_schedule must be one of .*'step'"),
           ('model.contrastive_weight', -1.0, 'contrastive_weight must be >= 0, got -1.0'),
           ('model.contrastive_temperature', 0.0, 'contrastive_temperature must be > 0'),
           ('model.contrastive_rows', 'paper', r"contrastive_rows must be one of \('all', 'two_view'\)"),
           ('model.partner_jitter', -1.0, 'partner_jitter must be a distance >= 0'),
           # tiny_config's partner_centers is off: a jitter would move nothing.
           ('model.partner_jitter', 1.0, 'partner_jitter moves partner centres: it needs'),
           ('inference.keypoints', 'ground', r"inference.keypoints must be one of \('all', "
            r"'structure'\), got 'ground'")]
  for field, value, message in cases:
    config = tiny_config.copy_and_resolve_references()
    section, name = field.split('.')
    config[section][name] = value
    with pytest.raises(checks.ConfigError, match=message):
      checks.check_config(config)



def test_a_stored_config_with_a_flag_that_is_not_a_bool_is_refused(tiny_config):
  # A config read from JSON is typed by its values: a string where True/False belongs.
  raw = tiny_config.to_dict()
  raw['model']['partner_centers'] = 'yes'
  with pytest.raises(checks.ConfigError,
                     match="model.partner_centers must be True or False, got 'yes'"):
    checks.check_config(ml_collections.ConfigDict(raw))

def _each_data_value_fails(config, cases):
  """Each (data field, value, message) of `cases`, set alone on `config`, is refused."""
  for name, value, message in cases:
    bad = config.copy_and_resolve_references()
    bad.data[name] = value
    with pytest.raises(checks.ConfigError, match=message):
      checks.check_config(bad)


def test_rescan_pair_errors_name_the_value(tiny_config):
  tiny_config.data.rescan_rate = 0.5
  checks.check_config(tiny_config)
  cases = [('rescan_rate', 2.0, r'data.rescan_rate must be in \[0, 1\]'),
           ('rescan_sensors', ('vlp16', 'hdl128'), r"rescan_sensors: unknown \['hdl128'\]"),
           ('rescan_sensors', (), 'rescan_sensors: unknown'),
           ('rescan_shift', (10.0, 5.0), 'rescan_shift must be'),
           ('rescan_views', 0, 'rescan_views must be >= 1'),
           ('rescan_beams', 'trace', r"rescan_beams must be one of \('select', 'cast'\)")]
  _each_data_value_fails(tiny_config, cases)
  tiny_config.objective = 'triplet'
  with pytest.raises(checks.ConfigError, match='for the self-supervised objective'):
    checks.check_config(tiny_config)


def test_mined_pair_errors_name_the_value(tiny_config, tmp_path):
  # The file is the run's input, read when training starts (test_mining): a config naming
  # one not mined yet is still a valid config.
  tiny_config.data.pairs = str(tmp_path / 'mined.csv')
  checks.check_config(tiny_config)
  tiny_config.data.rescan_rate = 0.5
  with pytest.raises(checks.ConfigError, match='two different second views'):
    checks.check_config(tiny_config)
  tiny_config.data.rescan_rate = 0.0
  cases = [('pairs_rate', 0.0, r'data.pairs_rate must be in \(0, 1\]'),
           ('pairs_weight', 'far', "data.pairs_weight must be one of .*'far'"),
           ('pairs_links', 0, 'data.pairs_links must be a whole number >= 1, got 0')]
  _each_data_value_fails(tiny_config, cases)


def test_batch_must_split_over_devices(tiny_config):
  tiny_config.train.batch_size = 3
  with pytest.raises(checks.ConfigError,
                     match=r'batch_size \(3\) must be divisible by the 2 devices of the run'):
    checks.check_config(tiny_config, num_devices=2)


def test_runs_from_before_a_model_key_existed_resume_with_its_old_value(tiny_config):
  tiny_config.objective = 'triplet'
  stored = json.loads(json.dumps(tiny_config.to_dict()))
  for section, key in upgrade.RUN_KEYS:
    if section == 'model':
      del stored['model'][key]
  tiny_config.model.triplet_hinge = 'cluster'
  checks.check_resumable(tiny_config, stored, 'old_run')      # what old runs used: accepted
  tiny_config.model.triplet_hinge = 'cloud'
  with pytest.raises(checks.ConfigError,
                     match="old_run holds a run with model.triplet_hinge='cluster'"):
    checks.check_resumable(tiny_config, stored, 'old_run')
  stored['objective'] = 'self_supervised'    # never used the triplet loss: nothing to refuse
  checks.check_resumable(tiny_config, stored, 'old_run')
  # A self-supervised run from before the full-circle options drew Gaussian angles.
  tiny_config.model.self_rotation = 'uniform'
  with pytest.raises(checks.ConfigError, match="model.self_rotation='gaussian'"):
    checks.check_resumable(tiny_config, stored, 'old_run')


def test_config_upgrade_fills_only_missing_keys_with_what_old_runs_used():
  today = paper.get_config()
  for section, key in upgrade.RUN_KEYS:      # every key the upgrade knows exists today
    assert key in today[section], (section, key)
  assert upgrade.upgrade(today).to_dict() == json.loads(json.dumps(today.to_dict()))
  old = json.loads(json.dumps(today.to_dict()))
  del old['inference'], old['model']['self_rotation'], old['train']['lr_schedule']
  old['model']['orientation_head'] = 'equivariant'
  up = upgrade.upgrade(old)
  assert up.model.self_rotation == 'gaussian' and up.train.lr_schedule == 'constant'
  assert up.model.orientation_head == 'equivariant'            # stored values stay
  assert up.inference.to_dict() == {'num_samples': 0, 'draws': 1, 'voxel_size': 0.2,
                                    'keypoints': 'all'}
  old_set = {'test_kitti': {'num_scenes': 1}, 'test_oxford': {'num_scenes': 1}}
  assert upgrade.upgrade_synthetic(old_set) == {
      'test_kitti': {'num_scenes': 1, 'random_yaw': False},
      'test_oxford': {'num_scenes': 1, 'sensor': 'spinning', 'line_spacing': 0.2}}


def test_every_training_config_of_the_project_passes_its_checks():
  """Each training config stands alone and is valid as shipped (the docs' commands)."""
  names = []
  for path in sorted(Path(cli.configs_dir()).rglob('*.py')):
    spec = importlib.util.spec_from_file_location(f'config_{path.stem}', path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    config = module.get_config() if hasattr(module, 'get_config') else None
    if config is not None and 'model' in config and 'train' in config:
      checks.check_config(config, num_devices=1)
      names.append(path.stem)
  assert {'paper', 'paper_small', 'ours', 'ours_detector', 'feat3dnet_small_varied',
          'feat3dnet', 'adapt', 'rescan', 'ours_rescan', 'ours_mined'} <= set(names)
