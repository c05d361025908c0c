"""Settings shared by every evaluation: which checkpoints, which keypoint x descriptor
rows, RANSAC, seeds and the FPFH neighbour cap, and an empty `evals`. The evaluation
configs (registration.py, precision.py, repeatability.py, descriptor_matching.py,
reproduce.py) start from it and name their evaluations under `evals`
(ssd_jax/evaluation/evaluators.py lists the types); not run on its own.
"""

import ml_collections


def get_config() -> ml_collections.ConfigDict:
  config = ml_collections.ConfigDict()
  # Data paths of the evals are relative to this folder ('' = the working directory).
  config.data_root = ''
  # Names are Python identifiers so that `--config.checkpoints.feat3dnet=DIR` parses.
  # Each is a shipped pretrained model's name (ssd_jax/weights/<name>, see
  # ssd_jax.pretrained.SHIPPED), an export folder or a training run directory.
  config.checkpoints = ml_collections.ConfigDict({
      'ours': 'ours',                       # self-supervised (configs/training/ours.py)
      # Weakly supervised 3DFeat-Net baseline on ours' network (configs/training/feat3dnet.py).
      'feat3dnet': 'feat3dnet',
      'ours_detector': 'ours_detector',     # self-supervised detector (extension)
      # ours matching across sensors (configs/training/ours_rescan.py)
      'ours_rescan': 'ours_rescan',
      'ours_mined': 'ours_mined',           # ours trained on mined pairs (its config in training/)
  })
  # keypoints+descriptor[+estimator[+verify[+bev]]]: keypoints iss | random | auto |
  # structure | a checkpoint name (its detector); descriptors fpfh | a checkpoint name;
  # estimator rigid (the paper's) | upright. A row with 'verify' runs the register
  # command's own path (`pipeline.Registrar` on the files); so do 'register',
  # 'register_fpfh' and 'register_descriptor' (evaluation/feature_store.py,
  # COMMAND_ROWS). The paper's Tables I/II and Fig. 4 rows:
  config.rows = ('iss+fpfh', 'iss+feat3dnet', 'iss+ours', 'feat3dnet+fpfh',
                 'feat3dnet+feat3dnet', 'feat3dnet+ours', 'ours_detector+fpfh',
                 'ours_detector+ours_detector')
  # Control for the learned detectors (not run by default, it doubles the FPFH work):
  # --config.rows="('random+fpfh',)".
  config.inlier_threshold = 1.0   # metres (RANSAC)
  config.confidence = 0.99
  config.max_trials = 10_000
  config.max_pairs = 0            # 0 = all pairs of every set (the first max_pairs otherwise)
  config.seed = 0                 # protocol rows: pair n's RANSAC seed * 1,000,003 + n
  config.fpfh_max_nn = 0          # neighbour cap of FPFH's 4 m searches (0: none, the paper's)
  config.num_keypoints = 1024     # farthest-point keypoints per cloud of the 'auto' rows
  # The upright rows' matches and samples (ssd_jax.registration.pipeline.SAMPLINGS): 'auto'
  # (the register command's: 'compatible' for a row's best pose, 'uniform' where a row
  # verifies its candidates), 'compatible' or 'uniform' (nearest neighbours, uniform draws).
  config.sampling = 'auto'
  config.level = 'none'           # 'ground': level each tilted scan first (register --level)
  config.evals = ml_collections.ConfigDict()
  return config


def registration(dataset, paper: str = 'none', title: str = 'Registration'):
  """An `evals` entry for Tables I / II; `paper` (oxford | kitti | none) picks the
  paper's rows printed beside. `dataset`: a folder, or a tuple tried in order."""
  return ml_collections.ConfigDict({'type': 'registration', 'dataset': dataset,
                                    'paper': paper, 'title': title})


def precision(dataset, title: str = 'Precision (Fig. 4)'):
  """An `evals` entry for the precision curve of Fig. 4."""
  return ml_collections.ConfigDict({
      'type': 'precision', 'dataset': dataset, 'title': title,
      'overlap_radius': 0.75,   # metres: keypoints of cloud 1 farther from cloud 2 don't count
      'read_at': 1.0,           # metres: the x the paper reads the curves at
  })


def repeatability(dataset, title: str = 'Keypoint repeatability'):
  """An `evals` entry: the share of cloud-1 keypoints with a cloud-2 keypoint within
  `radius` after the ground-truth alignment, per detector."""
  return ml_collections.ConfigDict({
      'type': 'repeatability', 'dataset': dataset, 'title': title,
      'keypoint_sources': ('iss', 'feat3dnet', 'ours_detector', 'random'),
      'radius': 0.5,            # metres
  })


def descriptor_matching(clusters, title: str = 'Table III: descriptor matching'):
  """An `evals` entry for Table III on the cluster pairs of `clusters`."""
  return ml_collections.ConfigDict({
      'type': 'descriptor_matching', 'clusters': clusters, 'title': title,
      'descriptors': ('fpfh', 'feat3dnet', 'ours'),   # fpfh or checkpoint names
      'radius': 2.0,            # metres: FPFH radius (learned: the model's own)
      'recall': 0.95,
      'r_th': (0.1, 0.2, 0.3, 0.4),   # metres: ISS keypoint within r_th of both centers
      # Cluster pairs are many and cheap: their own cap, not config.max_pairs (0 = all).
      'max_pairs': 0,
  })
