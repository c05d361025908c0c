"""Precision test (paper Fig. 4, docs/method.md §4) for every keypoint x descriptor row.

Command (the small synthetic Oxford-style set, after the README's main job):

    python -m experiments.evaluate --config=configs/evals/precision.py \
        --workdir=runs/precision_synthetic

It writes precision.csv (x = 0.1 ... 10 m) and precision.png, and prints each
row's precision at x = 1 m (the paper: ~15 % for both learned descriptors on
Oxford). On real data: `--config.evals.precision.dataset=/data/oxford/test`.
"""

import ml_collections

from ssd_jax.configs.evals import evaluation


def get_config() -> ml_collections.ConfigDict:
  config = evaluation.get_config()
  config.evals.precision = evaluation.precision('data_cache/synthetic_small/test_oxford')
  return config
