"""`ours_rescan`: the shipped `ours` fine-tuned, without labels, to match across sensors
and standpoints. Half of each batch's second branches are what another unit (16- to
128-beam, or a 120° solid state) sees of the training cloud from 2-30 m away
(`data.rescan_rate`, `datasets.RescanPairDataset`); PC2's cluster centres are the points
nearest PC1's (`model.partner_centers`), and an InfoNCE at those partners
(`model.contrastive_weight` 1) joins the paper's rotation loss. Still one unlabeled
cloud per pair: the re-scan is made from the cloud itself.

Command (the main job's synthetic set first):

    python -m experiments.train --config=configs/training/ours_rescan.py --workdir=runs/ours_rescan
    python -m experiments.export --run=runs/ours_rescan --out=ssd_jax/weights/ours_rescan

Expected (2-core CPU VM, ~27 minutes with a second run sharing the cores): the
descriptor alone (farthest-point keypoints, upright RANSAC, no verification) on the
cross-sensor test sets, synthetic 67.5 % (`ours` 51.7 %, FPFH 55.8 %; with
`--config.seed=1` 60.8 %), real 93.8 % (`ours` 92.7 %); the model card
(ssd_jax/weights/ours_rescan/MODEL_CARD.md) has the paper-protocol rows and the ablation.
"""

from ssd_jax.configs.experiments import rescan


def get_config():
  config = rescan.get_config()
  config.model.contrastive_weight = 1.0
  config.model.partner_centers = True
  return config
