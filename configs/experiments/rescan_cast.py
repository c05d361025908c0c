"""`configs/training/ours_rescan.py` with re-scans whose unit casts its own rays at the cloud's
surfaces (`data.rescan_beams='cast'`, `sensors.cast`) instead of keeping the cloud's points
that lie on its beams: the second view's ground carries the new unit's rings about its own
standpoint, not the training cloud's rings, so matching ring patterns no longer pays.

Command (the synthetic set comes first):

    python -m experiments.train --config=configs/experiments/rescan_cast.py \
        --workdir=runs/rescan_cast

Expected (descriptor alone: farthest-point keypoints, upright RANSAC with compatible
samples; ~23 minutes with a second run sharing the 2-core VM): synthetic cross-sensor
validation 60.0 %, test 59.2 % (`--config.seed=1`: 70.0 / 65.8 %; `ours_rescan` 70.8 / 65.0
and 67.5 / 60.8 %): no gain. docs/notes/cross_sensor.md has the table.
"""

from ssd_jax.configs.training import ours_rescan


def get_config():
  config = ours_rescan.get_config()
  config.data.rescan_beams = 'cast'
  return config
