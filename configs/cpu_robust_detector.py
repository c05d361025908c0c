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
  config.model.radius = 2.0   # the shipped ours_detector was trained on 2 m balls
  config.model.attention_in_cf = True
  config.train.num_steps = 2000
  return config
