"""Keypoint repeatability of ISS, the 3DFeat-Net detector and the self-supervised
detector: the share of cloud-1 keypoints with a cloud-2 keypoint within 0.5 m
after the ground-truth alignment.

Command (the small synthetic KITTI-style set):

    python -m experiments.evaluate --config=configs/evals/repeatability.py \
        --workdir=runs/repeatability_synthetic
"""

import ml_collections

from ssd_jax.configs.evals import evaluation


def get_config() -> ml_collections.ConfigDict:
  config = evaluation.get_config()
  config.evals.repeatability = evaluation.repeatability('data_cache/synthetic_small/test_kitti')
  return config
