"""`reproduce` on the README's small synthetic set in minutes on 2 CPU cores: the
evaluation of the README's main job.

Command (the main job first makes the data and trains runs/main_job):

    python -m experiments.evaluate --config=configs/evals/reproduce_small.py \
        --config.data_root=data_cache/synthetic_small --workdir=runs/reproduce_small

Every table and figure of the paper, each on the first `max_pairs` pairs of its set
(Tables I and II, Fig. 4, repeatability and Figs. 3, 5, 6: 8 Oxford-style and 8
KITTI-style pairs) and 1,000 of the 2,000 cluster pairs (Table III), with FPFH's 4 m
search capped at 200 neighbours (several times faster than 1,000), the shipped pretrained
models and the main job's own short run (row "Ours (this run)"). Each table says how
many pairs it used. Expected: ~4 minutes on the 2-core CPU VM (docs/reproduce.md).

The full-size reproduction on the same data (all 53 + 106 pairs, all 2,000 cluster
pairs; ~21 minutes on the 2-core CPU VM):

    python -m experiments.evaluate --config=configs/evals/reproduce_small.py \
        --config.data_root=data_cache/synthetic_small --workdir=runs/reproduce_full \
        --config.max_pairs=0 --config.evals.descriptor_matching.max_pairs=0
"""

from ssd_jax.configs.evals import reproduce


def get_config():
  config = reproduce.get_config()
  config.fpfh_max_nn = 200
  config.max_pairs = 8
  config.evals.descriptor_matching.max_pairs = 1000
  # The main job's own short training run, beside the shipped models.
  config.checkpoints.ours_run = 'runs/main_job'
  config.rows = (*config.rows, 'iss+ours_run')
  return config
