"""The self-supervised detector (an extension beyond the paper) on the robust config:
configs/cpu_robust.py with the CF weights multiplied by both clusters' attentions,
w_ij * a_i * b_j, so the attention head learns from single unlabeled clouds.

Command:

    python -m experiments.train --config=configs/cpu_robust_detector.py \
        --workdir=runs/cpu_robust_detector

It supplies the shipped `ours_detector` model (learned keypoints: attention + NMS).
"""

from ssd_jax.configs import cpu_robust


def get_config():
  config = cpu_robust.get_config()
  # The shipped ours_detector was trained before cpu_robust's 4 m balls, alpha 0.25,
  # cosine schedule and 4,096-point clouds: 2 m balls, alpha 1, a constant learning
  # rate, 2,048 points.
  config.model.radius = 2.0
  config.model.alpha = 1.0
  config.train.lr_schedule = 'constant'
  config.data.num_points = 2048
  config.model.attention_in_cf = True
  config.train.num_steps = 2000
  return config
