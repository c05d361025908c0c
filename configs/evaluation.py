"""Shared settings of every evaluation: which checkpoints, which keypoint x
descriptor rows, seeds and the FPFH neighbour cap. Imported by registration.py,
precision.py, descriptor_matching.py and reproduce.py; not run on its own.
"""

import ml_collections


def get_config() -> ml_collections.ConfigDict:
  config = ml_collections.ConfigDict()
  # Names are Python identifiers so that `--config.checkpoints.feat3dnet=DIR` parses.
  # Each is a shipped pretrained model's name (ssd_jax/weights/<name>, see
  # ssd_jax.pretrained.SHIPPED), an export folder or a training run directory.
  config.checkpoints = ml_collections.ConfigDict({
      'ours': 'ours',                       # self-supervised (configs/cpu_robust.py)
      # Weakly supervised 3DFeat-Net baseline (configs/feat3dnet_small_varied.py).
      'feat3dnet': 'feat3dnet',
      'ours_detector': 'ours_detector',     # self-supervised detector (extension)
  })
  # keypoints+descriptor: keypoints iss | random | a checkpoint name (its detector);
  # descriptors fpfh | a checkpoint name. The paper's Tables I/II and Fig. 4 rows:
  config.rows = ('iss+fpfh', 'iss+feat3dnet', 'iss+ours', 'feat3dnet+fpfh',
                 'feat3dnet+feat3dnet', 'feat3dnet+ours', 'ours_detector+fpfh',
                 'ours_detector+ours_detector')
  # Control for the learned detectors (not run by default, it doubles the FPFH work):
  # --config.rows="('random+fpfh',)" on experiments.evaluate_registration.
  # Detectors whose repeatability is measured (0.5 m after the ground-truth alignment).
  config.keypoint_sources = ('iss', 'feat3dnet', 'ours_detector', 'random')
  config.repeatability_radius = 0.5
  config.max_pairs = 0            # 0 = all pairs
  config.seed = 0                 # RANSAC samples of pair n use seed * 1,000,003 + n
  config.fpfh_max_nn = 1000       # neighbour cap of FPFH's searches
  return config
