"""Geometric registration benchmark (paper Tables I and II, docs/method.md §4).

Command (the small synthetic set, after the README's main job):

    python -m experiments.evaluate --config=configs/evals/registration.py \
        --workdir=runs/registration_synthetic

On real data, point the dataset at an Oxford test set (test_models/ +
groundtruths.txt) or a processed KITTI set (<seq>/groundtruths.txt), e.g.
`--config.evals.registration.dataset=/data/oxford/test --config.evals.registration.paper=oxford`.
Each row is `keypoints+descriptor`: keypoints `iss`, `random` or a checkpoint name
(its detector: attention + NMS); descriptors `fpfh` or a checkpoint name. Rows whose
checkpoint does not exist are reported as missing. Writes WORKDIR/registration.md,
.csv, registration_pairs.jsonl (one line per pair and row: RTE, RRE, success, trials,
inliers) and report.md.
"""

import ml_collections

from ssd_jax.configs.evals import evaluation


def get_config() -> ml_collections.ConfigDict:
  config = evaluation.get_config()
  config.evals.registration = evaluation.registration(
      'data_cache/synthetic_small/test_kitti', paper='kitti')
  return config
