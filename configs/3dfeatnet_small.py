"""The 3DFeat-Net baseline on the small synthetic set, in minutes on 2 CPU cores.

Commands (after the README's main job made data_cache/synthetic_small):

    python -m experiments.train --config=configs/3dfeatnet_small.py:pretrain \
        --workdir=runs/feat3dnet_small_pretrain
    python -m experiments.train --config=configs/3dfeatnet_small.py \
        --workdir=runs/feat3dnet_small

The reference recipe (configs/3dfeatnet_paper.py) shrunk as configs/cpu_small.py
shrinks the paper's: 2 triplets x 2,048 points, 256 clusters of 32 points, and a
learning rate of 1e-3 instead of 1e-5 so that a few hundred steps learn something.
"""

import importlib

from configs import cpu_small

paper_baseline = importlib.import_module('configs.3dfeatnet_paper')


def get_config(stage: str = 'full'):
  config = paper_baseline.get_config(stage)
  small = cpu_small.get_config()
  config.data = small.data
  for key in ('num_clusters', 'num_samples'):
    config.model[key] = small.model[key]
  config.train.batch_size = 2
  config.train.learning_rate = 1e-3
  config.train.log_every = 20
  config.train.eval_every = 100
  if stage == 'pretrain':
    config.train.num_steps = 600
    config.train.checkpoint_every = 200
  else:
    config.train.num_steps = 3000
    config.train.checkpoint_every = 500
    config.train.eval_every = 500
    config.train.init_from = 'runs/feat3dnet_small_pretrain'
  return config
