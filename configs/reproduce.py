"""Every evaluation of the paper on one data root, at the paper's settings.

Command:

    python -m experiments.reproduce --data_root=DIR --workdir=OUT --config=configs/reproduce.py

DIR may hold (each optional; the first existing candidate of `sets` is used):
  * an Oxford test set: DIR/test_oxford, DIR/oxford/test or DIR/oxford
    (test_models/ + groundtruths.txt)                 -> Table I, Fig. 4, Figs. 3 and 5
  * a processed KITTI set: DIR/test_kitti, DIR/kitti/test or DIR/kitti
    (<seq>/groundtruths.txt)                          -> Table II, Fig. 4 (KITTI), Fig. 6
  * descriptor-matching clusters: DIR/clusters or DIR/oxford/clusters
    (filenames.txt + <i>_0/1.bin)                     -> Table III and its text
The synthetic sets of `experiments.make_synthetic` have this layout. Checkpoints
are named in `checkpoints`; rows whose checkpoint is missing are reported as
such. OUT/report.md holds every table beside the paper's numbers, the figures
and what was skipped. configs/reproduce_small.py is the few-minute CPU variant.
"""

import ml_collections

from configs import descriptor_matching, precision, registration


def get_config() -> ml_collections.ConfigDict:
  config = registration.get_config()
  del config.dataset, config.paper     # found under --data_root; tables name their set
  config.sets = ml_collections.ConfigDict({
      'oxford': ('test_oxford', 'oxford/test', 'oxford'),
      'kitti': ('test_kitti', 'kitti/test', 'kitti'),
      'clusters': ('clusters', 'oxford/clusters'),
  })
  prec = precision.get_config()
  config.precision_sets = ('oxford', 'kitti')   # Fig. 4 is Oxford in the paper
  config.overlap_radius = prec.overlap_radius
  config.read_at = prec.read_at
  dm = descriptor_matching.get_config()
  del dm.clusters, dm.checkpoints, dm.fpfh_max_nn   # from `sets` and this config
  config.descriptor_matching = dm
  config.figures = ml_collections.ConfigDict({
      'keypoint_sources': ('iss', 'feat3dnet'),   # Fig. 3: on the first cloud of the first set
      'registration_rows': ('iss+ours', 'feat3dnet+ours'),   # Figs. 5-6: first pair per set
  })
  return config
