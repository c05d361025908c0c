"""The self-supervised detector (an extension beyond the paper): paper_small with the CF
weights multiplied by both clusters' predicted attentions, w_ij * a_i * b_j, so the
attention head learns from single unlabeled clouds.

Command (after the README's main job):

    python -m experiments.train --config=configs/experiments/paper_small_detector.py \
        --workdir=runs/paper_small_detector

Its detector then supplies the "Ours (self-sup. detector)" keypoint rows of
configs/evals/registration.py. The paper's authors report that their own attempt at
training attention this way failed; docs/notes/feat3dnet_baseline.md measures what it
does here.
"""

from ssd_jax.configs.training import paper_small


def get_config():
  config = paper_small.get_config()
  config.model.attention_in_cf = True
  return config
