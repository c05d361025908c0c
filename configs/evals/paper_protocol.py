"""The paper's protocol (ISS keypoints, nearest-neighbour matches, RANSAC over any
rotation) for every shipped descriptor and FPFH on the README's 64-beam sets, in one run.

Command (after the main job's synthetic set, `experiments.data.make_synthetic
--config=configs/data/synthetic_kitti_yaw.py --out=data_cache/synthetic_kitti_yaw` and
`experiments.data.make_real_pairs`):

    python -m experiments.evaluate --config=configs/evals/paper_protocol.py \
        --workdir=runs/paper_protocol

Each row is ISS + one descriptor: FPFH (1 m normals, 4 m features), `ours`, the
3DFeat-Net baseline `feat3dnet` (configs/training/feat3dnet.py: `ours`' network trained
with 3DFeat-Net's triplet loss), `ours_rescan` (configs/training/ours_rescan.py; 100 / 100 / 100 /
97.5 % on KITTI-style, any yaw, push-broom and real re-scans), `ours_mined`
(configs/training/ours_mined.py; 100 / 100 / 100 / 97.5 %) and `ours_detector`'s
descriptor. The tables give
success, RTE, RRE and RANSAC iterations per set, and success per 45-degree bin of the
pairs' relative yaw; the precision at 1 m of each row is in the Fig. 4 sections.
"""

from ssd_jax.configs.evals import evaluation

KITTI = 'data_cache/synthetic_small/test_kitti'
KITTI_YAW = 'data_cache/synthetic_kitti_yaw/test_kitti'
PUSHBROOM = 'data_cache/synthetic_small/test_oxford'
REAL = 'data_cache/real_pairs'


def get_config():
  config = evaluation.get_config()
  config.rows = ('iss+fpfh', 'iss+ours', 'iss+ours_rescan', 'iss+ours_mined', 'iss+feat3dnet',
                 'iss+ours_detector')
  config.evals.kitti = evaluation.registration(KITTI, title='KITTI-style synthetic')
  config.evals.kitti_yaw = evaluation.registration(
      KITTI_YAW, title='KITTI-style synthetic, each scan turned by a random yaw')
  config.evals.pushbroom = evaluation.registration(
      PUSHBROOM, title='Oxford-style push-broom synthetic')
  config.evals.real = evaluation.registration(REAL, title='Real re-scans')
  return config
