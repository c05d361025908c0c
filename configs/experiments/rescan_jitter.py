"""`configs/training/ours_rescan.py` with jittered partners: does training on partners up to 1 m
off (as far as registration's keypoints of two clouds lie from each other) help the
descriptor alone across sensors?

Command (the synthetic set comes first):

    python -m experiments.train --config=configs/experiments/rescan_jitter.py \
        --workdir=runs/rescan_jitter [--config.seed=1]

`model.partner_jitter` 1 m (`objective.partner_indices`): each of PC2's centres is its
point nearest a point drawn in the 1 m horizontal disc around PC1's turned centre; the
InfoNCE's positives stay within 1 m (RANSAC's inlier distance). Everything else as
`ours_rescan`, 3,000 steps. Expected (descriptor alone: farthest-point keypoints, upright
RANSAC; 34 minutes each with two runs sharing the 2-core VM): synthetic cross-sensor
validation 63.3 / 54.2 % (seeds 0 / 1; `ours_rescan` 65.0), test 60.0 / 56.7 % (`ours_rescan`
65.0 / 55.0): no gain, inside the seed spread. docs/notes/cross_sensor.md has the table.
"""

from ssd_jax.configs.training import ours_rescan


def get_config():
  config = ours_rescan.get_config()
  config.model.partner_jitter = 1.0
  return config
