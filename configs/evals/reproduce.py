"""Every evaluation of the paper on one data root, at the paper's settings.

Command:

    python -m experiments.evaluate --config=configs/evals/reproduce.py \
        --config.data_root=DIR --workdir=OUT

DIR may hold (each optional; the first existing candidate is used):
  * an Oxford test set: DIR/test_oxford, DIR/oxford/test or DIR/oxford
    (test_models/ + groundtruths.txt)                 -> Table I, Fig. 4, Figs. 3 and 5
  * a processed KITTI set: DIR/test_kitti, DIR/kitti/test or DIR/kitti
    (<seq>/groundtruths.txt)                          -> Table II, Fig. 4 (KITTI), Fig. 6
  * descriptor-matching clusters: DIR/clusters or DIR/oxford/clusters
    (filenames.txt + <i>_0/1.bin)                     -> Table III and its text
The synthetic sets of `experiments.data.make_synthetic` have this layout. Checkpoints
are named in `checkpoints`; rows whose checkpoint is missing are reported as
such. OUT/report.md holds every table beside the paper's numbers, the figures
and what was skipped. configs/evals/reproduce_small.py is the few-minute CPU variant.
"""

import ml_collections

from ssd_jax.configs.evals import evaluation

OXFORD = ('test_oxford', 'oxford/test', 'oxford')
KITTI = ('test_kitti', 'kitti/test', 'kitti')


def get_config() -> ml_collections.ConfigDict:
  config = evaluation.get_config()
  evals = config.evals
  evals.table1_oxford = evaluation.registration(
      OXFORD, 'oxford', 'Table I: registration on Oxford-style pairs')
  evals.table2_kitti = evaluation.registration(
      KITTI, 'kitti', 'Table II: registration on KITTI-style pairs')
  evals.fig4_precision_oxford = evaluation.precision(
      OXFORD, 'Fig. 4: precision on oxford-style pairs')   # Fig. 4 is Oxford in the paper
  evals.fig4_precision_kitti = evaluation.precision(KITTI, 'Fig. 4: precision on kitti-style pairs')
  evals.repeatability_oxford = evaluation.repeatability(
      OXFORD, 'Keypoint repeatability on oxford-style pairs')
  evals.repeatability_kitti = evaluation.repeatability(
      KITTI, 'Keypoint repeatability on kitti-style pairs')
  evals.descriptor_matching = evaluation.descriptor_matching(('clusters', 'oxford/clusters'))
  evals.figures = ml_collections.ConfigDict({
      'type': 'figures', 'title': 'Figures 3, 5 and 6',
      'sets': {'oxford': OXFORD, 'kitti': KITTI},
      'keypoint_sources': ('iss', 'feat3dnet'),   # Fig. 3: the first cloud of the first set
      'registration_rows': ('iss+ours', 'feat3dnet+ours'),   # Figs. 5-6: first pair per set
  })
  return config
