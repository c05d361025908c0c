"""Label-free adaptation of the register command's model (`pretrained.DEFAULT`,
`ours_mined`) to a user's own sensor: fine-tune every weight on a folder of unlabeled scans
from that sensor (no poses, no labels).

Command (what `experiments.adapt` runs, with its mining, model card and export):

    python -m experiments.adapt --scans=/data/my_vlp16_drive --out=exports/my_vlp16

`configs/training/ours.py` (the recipe of `ours`) started from that model's weights
(`--init`), at a third of its learning rate, decayed to 0 over 1,500 steps. The command
first mines pairs of the drive (`experiments.mine`) and sets `data.pairs` to them: half of
the second branches are then a real second scan of the place (`data.pairs_rate` 0.5). As
`ours_rescan`, PC2's centres are the partners of PC1's and an InfoNCE at them joins the
rotation loss (`model.partner_centers`, `model.contrastive_weight` 1). A drive of more than
`mining.max_scans` scans is mined on every k-th; after half the steps the model trained so
far mines the next two doubled gaps (`mining.widen_rounds`, EYOC's widening) and the rest
train on every kept pair. Last, the command sets the export's `inference.keypoints`: 'all'
where the adapted descriptor alone registers more of 32 chained mined pairs past the
miner's gaps from all points than from the structure above the ground
(`adaptation.keypoint_choice`), else 'structure'. Each scan must be one sweep centred on
its sensor (z up), in capture order by name.

Expected (`configs/evals/adaptation_os0.py`: a unit no shipped model saw): the descriptor
alone 55.2 -> 70.8 %; docs/notes/cross_sensor.md and docs/notes/real_drives.md have the
tables (VLP-16, OS0-64, a Livox drive) and the times.
"""

import ml_collections

from ssd_jax import pretrained
from ssd_jax.configs.training import ours as ours_config


def get_config():
  config = ours_config.get_config()
  config.data.path = ''              # set by --scans
  config.data.eval_path = ''
  config.train.init_from = pretrained.DEFAULT
  config.train.init_scope = 'model'
  config.model.contrastive_weight = 1.0
  config.model.partner_centers = True
  config.train.learning_rate = 3e-4
  config.train.num_steps = 1_500
  config.train.eval_every = 500
  config.train.checkpoint_every = 500
  # The command's mining (`registration.mining`): a drive thinned to max_scans scans (a
  # pair costs a registration, ~1.5 s on 2 cores, ~4 pairs a scan), and widen_rounds
  # rounds in which the model trained so far mines the next two doubled gaps.
  config.mining = ml_collections.ConfigDict({'max_scans': 120, 'widen_rounds': 1})
  return config
