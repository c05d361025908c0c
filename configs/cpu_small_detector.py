"""The self-supervised detector (an extension beyond the paper): cpu_small with the CF
weights multiplied by both clusters' predicted attentions, w_ij * a_i * b_j, so the
attention head learns from single unlabeled clouds.

Command (after the README's main job):

    python -m experiments.train --config=configs/cpu_small_detector.py \
        --workdir=runs/cpu_small_detector

Its detector then supplies the "Ours (self-sup. detector)" keypoint rows of
configs/registration.py. The paper's authors report that their own attempt at
training attention this way failed; docs/feat3dnet_baseline.md measures what it
does here.
"""

from ssd_jax.configs import cpu_small


def get_config():
  config = cpu_small.get_config()
  config.model.attention_in_cf = True
  return config
