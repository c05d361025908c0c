"""A training split with turn-distinctive street furniture, for the triplet baseline.

Command (~40 s on 2 CPU cores):

    python -m experiments.data.make_synthetic --config=configs/experiments/synthetic_small_varied.py \
        --out=data_cache/synthetic_small_varied

`synthetic_small`'s 3 training streets (same seeds, same layout draws, ~210 clouds
every 6 m), with five times the sidewalk objects, drawn from eight kinds at random
yaws (boxes, bollard rows, benches, cabinets, boulders, tables, L-shaped low walls,
planters), and half of the parked cars at an angle. No test splits: models trained on
it are evaluated on `synthetic_small`'s. It exists because on `synthetic_small`'s
streets, whose objects face the street, a 2-4 m neighbourhood turned about z tells
places apart too weakly for 3DFeat-Net's stage 2 to learn under Rotate1D in a CPU-length
run (docs/notes/feat3dnet_baseline.md); configs/experiments/feat3dnet_small_varied.py trains on it.
"""

from ssd_jax.configs.data import synthetic_small


def get_config():
  config = synthetic_small.get_config()
  config.scene.clutter_scale = 5.0
  config.scene.varied_objects = True
  config.test_kitti.num_scenes = 0
  config.test_oxford.num_scenes = 0
  config.clusters.num_scenes = 0
  return config
