"""The small synthetic set of the README's main job (~1-2 minutes on 2 CPU cores).

Command:

    python -m experiments.data.make_synthetic --config=configs/data/synthetic_small.py \
        --out=data_cache/synthetic_small

3 training scenes scanned every 6 m (~210 clouds), 2 KITTI-style test scenes
(~85 clouds, ~100 pairs), 2 Oxford-style test scenes (push-broom submaps, ~60 models,
~55 pairs) and 2,000 cluster pairs.
"""

from ssd_jax.configs.data import synthetic


def get_config():
  config = synthetic.get_config()
  config.train.num_scenes = 3
  config.train.spacing = 6.0
  config.test_kitti.num_scenes = 2
  config.test_oxford.num_scenes = 2
  config.clusters.num_scenes = 1
  config.clusters.num_pairs = 2000
  return config
