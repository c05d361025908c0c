"""Descriptor matching (paper Table III and its text, docs/method.md §4).

Command (the small synthetic cluster set, after the README's main job):

    python -m experiments.evaluate --config=configs/evals/descriptor_matching.py \
        --workdir=runs/descriptor_matching_synthetic

It prints and writes the FPR at 95 % recall on all pairs and on the ISS-filtered
pairs (r_th = 0.1 ... 0.4 m, with the surviving positive / negative counts) as
descriptor_matching.md / .csv, the ROC curves as descriptor_matching_roc.png and the
per-pair distances as descriptor_matching_distances.npz.
The paper: ours 66.33 % on all 30,000 Oxford pairs, 3DFeat-Net 36.84 %.

Expected (2-core CPU VM, ~4 min; the shipped models, all 2,000 pairs): FPFH 45.0 %,
3DFeat-Net (`feat3dnet`) 56.9 %, ours 68.5 %.
"""

import ml_collections

from ssd_jax.configs.evals import evaluation


def get_config() -> ml_collections.ConfigDict:
  config = evaluation.get_config()
  config.evals.descriptor_matching = evaluation.descriptor_matching(
      'data_cache/synthetic_small/clusters')
  return config
