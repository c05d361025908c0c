"""The full Oxford-style test set alone: push-broom submaps of configs/data/synthetic.py's
4 test scenes.

Command:

    python -m experiments.data.make_synthetic --config=configs/experiments/synthetic_oxford.py \
        --out=data_cache/synthetic_oxford

4 streets, each driven down and back by an LMS-151-like line scanner; a 60 m submap
every 10 m of each pass, in the frame the vehicle reported at its centre line, 16,384
points, randomly turned about z (~120 models, ~230 pairs). Only this test set is
written. Used by experiments.learning_curve as `--set=oxford_full=data_cache/synthetic_oxford/test_oxford`.
"""

from ssd_jax.configs.data import synthetic


def get_config():
  config = synthetic.get_config()
  config.train.num_scenes = 0
  config.test_kitti.num_scenes = 0
  config.clusters.num_scenes = 0
  config.test_oxford.sensor = 'pushbroom'
  return config
