"""The paper's self-supervised setting at a size that learns within minutes on 2 CPU
cores (Gaussian self-rotation, 3DFeat-Net's orientation head, both branches the same
points). configs/training/ours.py adds this project's full-circle remedies.

Command (the synthetic set comes first):

    python -m experiments.data.make_synthetic --config=configs/data/synthetic_small.py \
        --out=data_cache/synthetic_small
    python -m experiments.train --config=configs/training/paper_small.py --workdir=runs/paper_small

It trains on the synthetic training folder and tracks the CF rotation error on
the held-out synthetic Oxford-style test models. Real scans work the same way:
`--config.data.path=../shared/data/kitti_object_velodyne`.

Batch 2 x 2,048 points, 256 clusters of 32 points, 600 steps (~0.25 s/step
on 2 cores, ~2.7 minutes). Expected on the small synthetic set (seed 0):
the training CF rotation error falls from ~11.5 degrees
(step 20) to ~5 degrees (step 600); on the held-out test models it falls from
~7.3 degrees (step 100) to ~2.4 degrees.
"""

from ssd_jax.configs.training import paper


def get_config():
  config = paper.get_config()
  config.data.path = 'data_cache/synthetic_small/train'
  config.data.eval_path = 'data_cache/synthetic_small/test_oxford/test_models'
  config.data.num_points = 2048
  config.model.num_clusters = 256
  config.model.num_samples = 32
  config.train.batch_size = 2
  config.train.num_steps = 600
  config.train.log_every = 20
  config.train.eval_every = 100
  config.train.checkpoint_every = 200
  return config
