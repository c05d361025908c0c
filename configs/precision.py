"""Precision test (paper Fig. 4, docs/method.md §4) for every keypoint x descriptor row.

Command (the small synthetic Oxford-style set, after the README's main job):

    python -m experiments.precision --config=configs/precision.py \
        --workdir=runs/precision_synthetic

It writes precision.csv (x = 0.1 ... 10 m) and precision.png, and prints each
row's precision at x = 1 m (the paper: ~15 % for both learned descriptors on
Oxford). On real data: `--config.dataset=/data/oxford/test`.
"""

import ml_collections

from configs import evaluation


def get_config() -> ml_collections.ConfigDict:
  config = evaluation.get_config()
  config.dataset = 'data_cache/synthetic_small/test_oxford'
  config.overlap_radius = 0.75    # metres: keypoints of cloud 1 farther from cloud 2 don't count
  config.read_at = 1.0            # metres: the x the paper reads the curves at
  return config
