"""The self-supervised detector (an extension beyond the paper): paper_small's paper setting
with the whole circle of self-rotation, the equivariant orientation head and branch
resampling, and the CF weights multiplied by both clusters' attentions, w_ij * a_i * b_j,
so the attention head learns from single unlabeled clouds. 2 m balls, alpha 1, a constant
learning rate, 2,048 training points, 2,000 steps.

Command:

    python -m experiments.train --config=configs/training/ours_detector.py \
        --workdir=runs/ours_detector

It supplies the shipped `ours_detector` model (learned keypoints: attention + NMS; its
card has its results).
"""

from ssd_jax.configs.training import paper_small


def get_config():
  config = paper_small.get_config()
  config.model.self_rotation = 'uniform'
  config.model.orientation_head = 'equivariant'
  config.model.branch_dropout = 0.5
  config.model.branch_crop_shift = 4.0
  config.model.branch_crop_radius = 16.0
  config.model.independent_centers = True
  config.model.attention_in_cf = True
  # Describe with 64 points per cluster, averaged over 4 samplings of each ball.
  config.inference.num_samples = 64
  config.inference.draws = 4
  config.train.num_steps = 2000
  config.train.eval_every = 500
  config.train.checkpoint_every = 1000
  config.train.keep_checkpoints = 100
  return config
