"""Geometric registration benchmark (paper Tables I and II, docs/method.md §4).

Command (the small synthetic set, after the README's main job):

    python -m experiments.evaluate_registration --config=configs/registration.py \
        --workdir=runs/registration_synthetic

On real data, point `dataset` at an Oxford test set (test_models/ +
groundtruths.txt) or a processed KITTI set (<seq>/groundtruths.txt), e.g.
`--config.dataset=/data/oxford/test --config.paper=oxford`. Each row is
`keypoints+descriptor`: keypoints `iss`, `random` or a checkpoint name (its
detector: attention + NMS); descriptors `fpfh` or a checkpoint name. Rows whose
checkpoint does not exist are reported as missing.
"""

import ml_collections

from configs import evaluation


def get_config() -> ml_collections.ConfigDict:
  config = evaluation.get_config()
  config.dataset = 'data_cache/synthetic_small/test_kitti'
  config.paper = 'kitti'          # paper rows to print beside: oxford | kitti | none
  config.inlier_threshold = 1.0   # metres
  config.confidence = 0.99
  config.max_trials = 10_000
  return config
