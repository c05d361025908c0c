"""The shipped `ours` fine-tuned on its own training set with the paper's pair (a cloud and
its turned copy): the control at equal steps of every fine-tune in docs/notes/cross_sensor.md.

Command (the synthetic set comes first):

    python -m experiments.train --config=configs/experiments/finetune.py --workdir=runs/finetune

`configs/training/ours.py` (the recipe of `ours`) started from `ours`' weights (every weight:
`train.init_scope='model'`) at a third of its learning rate, decayed to 0 by a cosine over
3,000 steps. Expected (validation pairs, farthest-point keypoints, upright RANSAC, no
verification): real cross-sensor 94.8 %, synthetic 45.0 % (`ours`: 91.7, 43.3).
"""

from ssd_jax.configs.training import ours as ours_config


def get_config():
  config = ours_config.get_config()
  config.train.init_from = 'ours'
  config.train.init_scope = 'model'
  config.train.learning_rate = 3e-4
  config.train.num_steps = 3_000
  config.train.checkpoint_every = 500
  return config
