"""Label-free adaptation of the shipped `ours` to a user's own sensor: fine-tune every
weight on a folder of unlabeled scans from that sensor (no poses, no labels).

Command (what `experiments.adapt` runs, with its mining, model card and export):

    python -m experiments.adapt --scans=/data/my_vlp16_drive --out=exports/my_vlp16

`configs/ours.py` (the recipe of `ours`: the self-rotation over the whole circle,
two samplings of each scan in the two branches) started from `ours`' weights, at a third
of its learning rate, decayed to 0 over 1,500 steps. The command first mines pairs of the
drive (`experiments.mine`) and sets `data.pairs` to them: half of the second branches are
then a real second scan of the place (`data.pairs_rate` 0.5). As `ours_rescan`, PC2's
centres are the partners of PC1's and an InfoNCE at them joins the rotation loss
(`model.partner_centers`, `model.contrastive_weight` 1). A drive of more than
`mining.max_scans` scans is mined on every k-th; after half the steps the model trained
so far mines the next two doubled gaps (`mining.widen_rounds`, EYOC's widening) and the
rest train on every kept pair. Last, the command sets the
export's `inference.keypoints`: 'structure' (keypoints above the ground) where the
adapted descriptor alone registers more of 32 chained mined pairs past the miner's gaps
from there than from all points (`registration.keypoint_choice`), else 'all'. Each scan
must be one sweep centred on its sensor (z up), in capture order by name.
Expected (every scan mined, no widening: `--config.mining.max_scans=210
--config.mining.widen_rounds=0`; 210 VLP-16 scans, 96 held-out VLP-16 pairs,
`configs/evals/adaptation.py`): the
descriptor alone with uniform samples 38.5 % with `ours` -> 49.0 / 47.9 % (seeds 0 / 1;
without the InfoNCE and partner centres 46.9 / 44.8 %; `--pairs=none` 46.9 %), with the
evaluation's default samples 44.8 -> 50.0 % (seed 0; from all points, before the
keypoint choice). On a unit no shipped model saw (210 OS0-64 scans, 96 held-out OS0-64
pairs, `configs/evals/adaptation_os0.py`) 55.2 -> 70.8 %: the choice picked the structure
(4 against 16 of the 32 chained pairs registered); from all points the adapted weights
register 56.2 %, `ours` from the structure 63.5 %. docs/notes/cross_sensor.md has the
tables and the times.
"""

import ml_collections

from ssd_jax.configs import ours as ours_config


def get_config():
  config = ours_config.get_config()
  config.data.path = ''              # set by --scans
  config.data.eval_path = ''
  config.train.init_from = 'ours'
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
