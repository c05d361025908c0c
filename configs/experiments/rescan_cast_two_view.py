"""`configs/experiments/rescan_cast.py` with the InfoNCE on the re-scan rows alone
(`model.contrastive_rows='two_view'`): the paper's pair (a cloud and its turned copy, the
same rings in both branches) keeps the rotation loss but no longer rewards matching a
scan's rings, and the re-scans carry the new unit's own rings (`data.rescan_beams='cast'`).

Command (the synthetic set comes first):

    python -m experiments.train --config=configs/experiments/rescan_cast_two_view.py \
        --workdir=runs/rescan_cast_two_view

Expected (descriptor alone, upright RANSAC with compatible samples; ~40 minutes with
three other jobs sharing the 2-core VM): synthetic cross-sensor validation 64.2 %, test
64.2 % (`--config.seed=1`: 64.2 / 60.0 %; `ours_rescan` 70.8 / 65.0 and 67.5 / 60.8 %):
no gain. docs/notes/cross_sensor.md has the table.
"""

from ssd_jax.configs.experiments import rescan_cast


def get_config():
  config = rescan_cast.get_config()
  config.model.contrastive_rows = 'two_view'
  return config
