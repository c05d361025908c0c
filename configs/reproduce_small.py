"""`reproduce` on the README's small synthetic set in minutes on 2 CPU cores.

Command (the README's main job, which first makes the data and trains runs/main_job):

    python -m experiments.evaluate --config=configs/reproduce_small.py \
        --config.data_root=data_cache/synthetic_small --workdir=runs/reproduce_small

All 53 Oxford-style and 106 KITTI-style pairs and all 2,000 cluster pairs, with
FPFH's 4 m search capped at 200 neighbours (several times faster than 1,000), the
shipped pretrained models and the main job's own short run (row "Ours (this run)").
"""

from ssd_jax.configs import reproduce


def get_config():
  config = reproduce.get_config()
  config.fpfh_max_nn = 200
  # The main job's own short training run, beside the shipped models.
  config.checkpoints.ours_run = 'runs/main_job'
  config.rows = (*config.rows, 'iss+ours_run')
  return config
