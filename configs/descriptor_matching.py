"""Descriptor matching (paper Table III and its text, docs/method.md §4).

Command (the small synthetic cluster set, after the README's main job):

    python -m experiments.descriptor_matching --config=configs/descriptor_matching.py \
        --workdir=runs/descriptor_matching_synthetic

It prints and writes the FPR at 95 % recall on all pairs and on the ISS-filtered
pairs (r_th = 0.1 ... 0.4 m, with the surviving positive / negative counts) as
descriptor_matching.md / .csv, and the ROC curves as descriptor_matching_roc.png.
The paper: ours 66.33 % on all 30,000 Oxford pairs, 3DFeat-Net 36.84 %.
"""

import ml_collections

from configs import evaluation


def get_config() -> ml_collections.ConfigDict:
  base = evaluation.get_config()
  config = ml_collections.ConfigDict()
  config.clusters = 'data_cache/synthetic_small/clusters'
  config.checkpoints = base.checkpoints
  config.descriptors = ('fpfh', 'feat3dnet', 'ours')   # fpfh or checkpoint names
  config.radius = 2.0             # metres: FPFH radius (learned: the model's own, 2 m here)
  config.recall = 0.95
  config.r_th = (0.1, 0.2, 0.3, 0.4)   # metres: ISS keypoint within r_th of both centers
  config.max_pairs = 0            # 0 = all pairs (the first max_pairs otherwise)
  config.fpfh_max_nn = base.fpfh_max_nn
  return config
