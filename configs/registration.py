"""Geometric registration benchmark (paper Tables I and II, REFERENCE §4-6).

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


def get_config() -> ml_collections.ConfigDict:
  config = ml_collections.ConfigDict()
  config.dataset = 'data_cache/synthetic_small/test_kitti'
  config.paper = 'kitti'          # paper rows to print beside: oxford | kitti | none
  config.checkpoints = ml_collections.ConfigDict({
      'ours': 'runs/cpu_small',               # self-supervised (this paper)
      '3dfeatnet': 'runs/3dfeatnet_small',    # weakly supervised baseline
  })
  config.rows = ('iss+fpfh', 'iss+3dfeatnet', 'iss+ours', '3dfeatnet+fpfh', '3dfeatnet+3dfeatnet',
                 '3dfeatnet+ours')
  config.max_pairs = 0            # 0 = all pairs
  config.seed = 0                 # RANSAC samples of pair n use seed * 1,000,003 + n
  config.inlier_threshold = 1.0   # metres
  config.confidence = 0.99
  config.max_trials = 10_000
  config.fpfh_max_nn = 1000       # neighbour cap of FPFH's 4 m searches
  return config
