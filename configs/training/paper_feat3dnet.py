"""3DFeat-Net's weakly supervised training (the baseline, docs/method.md §5), two stages.

Commands (Oxford RobotCar as processed by 3DFeat-Net):

    # stage 1: descriptor only (no orientation, no attention), 2 epochs
    python -m experiments.train --config=configs/training/paper_feat3dnet.py:pretrain \
        --workdir=runs/feat3dnet_paper_pretrain --config.data.path=/data/oxford/train/train.txt
    # stage 2: the full model, descriptor weights from stage 1, detector fresh, ~70 epochs
    python -m experiments.train --config=configs/training/paper_feat3dnet.py \
        --workdir=runs/paper_feat3dnet --config.data.path=/data/oxford/train/train.txt

Triplets (anchor, positive < 10 m, negative: neither positive nor non-negative)
from train.txt; the attention-weighted triplet loss with margin 0.2 (one hinge on
the attention-weighted sums of each triplet, as 3DFeat-Net's released code); batch 6
triplets of 4,096 points, 512 FPS clusters of 64 points within 2 m, D = 32;
Adam 1e-5; Jitter, RotateSmall and Shift, plus Rotate1D in stage 2. With 21,875
training clouds an epoch is ~3,650 steps. The reference's released model is what
the paper compares with; this config trains the same recipe here.
"""

from ssd_jax.configs.training import paper

EPOCH_STEPS = 3650   # 21,875 Oxford training clouds / batch 6


def get_config(stage: str = 'full'):
  if stage not in ('pretrain', 'full'):
    raise ValueError(f"stage must be 'pretrain' or 'full', got {stage!r}")
  config = paper.get_config()
  config.objective = 'triplet'
  config.model.margin = 0.2
  config.train.learning_rate = 1e-5
  if stage == 'pretrain':
    config.model.use_orientation = False
    config.model.augmentations = ('jitter', 'rotate_small', 'shift')
    config.train.num_steps = 2 * EPOCH_STEPS
  else:
    config.model.augmentations = ('jitter', 'rotate_small', 'shift', 'rotate_1d')
    config.train.num_steps = 70 * EPOCH_STEPS
    config.train.init_from = 'runs/feat3dnet_paper_pretrain'
  return config
