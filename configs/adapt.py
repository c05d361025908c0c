"""Label-free adaptation of the shipped `ours` to a user's own sensor: fine-tune every
weight on a folder of unlabeled scans from that sensor (no poses, no labels).

Command (what `experiments.adapt` runs, with its model card and export):

    python -m experiments.adapt --scans=/data/my_vlp16_scans --out=exports/my_vlp16

`configs/ours.py` (the recipe of `ours`: the self-rotation over the whole circle,
two samplings of each scan in the two branches) started from `ours`' weights, at a third
of its learning rate, decayed to 0 over 1,500 steps: under 10 minutes on 2 CPU
cores (docs/notes/benchmarks.md).
Each scan must be one sweep centred on its sensor (z up), as the sensor wrote it or
voxelised. docs/notes/cross_sensor.md measures it on 16-beam scans the shipped model never saw.
"""

from ssd_jax.configs import ours as ours_config


def get_config():
  config = ours_config.get_config()
  config.data.path = ''              # set by --scans
  config.data.eval_path = ''
  config.train.init_from = 'ours'
  config.train.init_scope = 'model'
  config.train.learning_rate = 3e-4
  config.train.num_steps = 1_500
  config.train.eval_every = 500
  config.train.checkpoint_every = 500
  return config
