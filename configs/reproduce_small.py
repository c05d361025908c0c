"""`reproduce` on the README's small synthetic set in minutes on 2 CPU cores.

Command (after the README's main job, which makes the data and runs/cpu_small):

    python -m experiments.reproduce --data_root=data_cache/synthetic_small \
        --workdir=runs/reproduce_small --config=configs/reproduce_small.py

All 53 Oxford-style and 106 KITTI-style pairs and all 2,000 cluster pairs, with
FPFH's 4 m searches capped at 200 neighbours (REFERENCE §10: ~10x faster than
the paper-faithful cap).
"""

from configs import reproduce


def get_config():
  config = reproduce.get_config()
  config.fpfh_max_nn = 200
  return config
