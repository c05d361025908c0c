"""The KITTI-style test set of `synthetic_small`, each scan turned by its own yaw.

Command:

    python -m experiments.data.make_synthetic --config=configs/data/synthetic_kitti_yaw.py \
        --out=data_cache/synthetic_kitti_yaw

The same 2 scenes, scans and pairs (~85 clouds, 106 pairs) as
data_cache/synthetic_small/test_kitti, but each scan is written in a frame turned
about the sensor's z axis by a uniform yaw, so the pairs' relative yaw covers
[0, 360) degrees evenly instead of ~0 and ~180 (two passes along a street). Only the
test set is written (~40 s). Used by experiments.learning_curve as `kitti_yaw`.
"""

from ssd_jax.configs.data import synthetic_small


def get_config():
  config = synthetic_small.get_config()
  config.train.num_scenes = 0
  config.test_oxford.num_scenes = 0
  config.clusters.num_scenes = 0
  config.test_kitti.random_yaw = True
  return config
