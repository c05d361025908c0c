"""Shared fixtures and helpers: the real scans beside the project, a tiny synthetic
dataset and a tiny training config."""

import os
from pathlib import Path

import pytest

from ssd_jax.infra import cli
from ssd_jax.configs.training import paper_small
from ssd_jax.configs.data import cross_sensor, synthetic
from ssd_jax.synthetic import dataset

# The tests in this process load what an earlier one compiled, as the commands they start
# do (the same folder): many build the same train step and registration kernels anew.
cli.enable_compilation_cache(cli.default_compilation_cache())

SHARED_DATA = Path(os.environ.get('SSD_JAX_SHARED_DATA',
                                  Path(__file__).resolve().parents[1] / '..' / 'shared' / 'data'))


def shared_path(*parts) -> Path:
  path = SHARED_DATA.joinpath(*parts)
  if not path.exists():
    pytest.skip(f'real data not found at {path} (set SSD_JAX_SHARED_DATA)')
  return path


def tiny_synthetic_config(seed=0):
  """The synthetic generator shrunk to seconds: one short scene per split."""
  config = synthetic.get_config()
  config.seed = seed
  config.scene_length = 80.0
  config.lidar.azimuth_step = 0.4
  config.train.num_scenes = 1
  config.train.spacing = 15.0
  config.test_kitti.num_scenes = 1
  config.test_oxford.num_scenes = 1
  config.test_oxford.num_points = 4096
  config.test_oxford.crop_radius = 15.0   # push-broom submaps of 30 m on the 80 m street
  config.test_oxford.spacing = 5.0
  config.clusters.num_scenes = 1
  config.clusters.num_pairs = 6
  config.clusters.min_points = 16
  return config


def tiny_cross_sensor_config():
  """`tiny_synthetic_config` with a cross-sensor section: VLP-16 and front120 against the
  HDL-64E, 5-20 m apart, one pair per cell of one scene."""
  config = tiny_synthetic_config()
  config.cross_sensor = cross_sensor.get_config().cross_sensor
  config.cross_sensor.sensors = ('vlp16', 'front120')
  config.cross_sensor.distance_bins = ((5.0, 10.0), (10.0, 20.0))
  config.cross_sensor.num_scenes = 1
  config.cross_sensor.pairs_per_cell = 1
  return config


@pytest.fixture(scope='session')
def synthetic_root(tmp_path_factory):
  """A tiny synthetic data root (train/ of 2 scenes, test_kitti/, test_oxford/, clusters/ with
  24 pairs)."""
  config = tiny_synthetic_config()
  config.clusters.num_pairs = 24
  config.train.num_scenes = 2     # clouds of another scene are the triplet negatives
  out = tmp_path_factory.mktemp('synthetic_root') / 'tiny'
  dataset.generate(config, out)
  return out


@pytest.fixture
def tiny_config():
  return tiny_config_dict()


def tiny_config_dict():
  """paper_small shrunk so one jitted step takes well under a second on 2 cores."""
  config = paper_small.get_config()
  config.progress_bar = False
  config.data.path = ''        # each test names its data
  config.data.eval_path = ''
  config.data.num_points = 512
  config.data.min_points = 16
  config.model.num_clusters = 64
  config.model.num_samples = 16
  config.train.batch_size = 2
  config.train.num_steps = 4
  config.train.log_every = 2
  config.train.checkpoint_every = 2
  config.train.eval_every = 2
  return config
