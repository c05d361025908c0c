"""`configs/training/ours_rescan.py` with every second branch a re-scan (`data.rescan_rate` 1, not
0.5): does more cross-view training help across sensors?

Command (the synthetic set comes first):

    python -m experiments.train --config=configs/experiments/rescan_only.py \
        --workdir=runs/rescan_only

Expected (descriptor alone: farthest-point keypoints, upright RANSAC; 24 minutes with a
second run sharing the 2-core VM): synthetic cross-sensor validation 56.7 % (`ours_rescan`
65.0 / 55.8 %, seeds 0 / 1): no gain. Its CF rotation error ends near 50° (`ours_rescan`
~20-30°): with no turned copy left in the batch, the rotation loss sees only the hard
pairs. docs/notes/cross_sensor.md has the table.
"""

from ssd_jax.configs.training import ours_rescan


def get_config():
  config = ours_rescan.get_config()
  config.data.rescan_rate = 1.0
  return config
