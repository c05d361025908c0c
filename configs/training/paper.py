"""The paper's self-supervised training settings (docs/method.md §2).

Command (Oxford RobotCar as processed by 3DFeat-Net):

    python -m experiments.train --config=configs/training/paper.py --workdir=runs/paper \
        --config.data.path=/data/oxford/train/train.txt

Batch 6 x 4,096 points, 512 FPS clusters of 64 points within 2 m, 32-D
descriptors, alpha 1, Adam 1e-3 for 72,500 steps (3DFeat-Net's 20 epochs),
self-rotation phi ~ N(0, 0.6^2) rad about z, jitter sigma 0.01 m. The paper
saves this model at step 72,500; its CF rotation error on held-out scans falls
below 1 degree within the first few thousand steps (docs/notes/speed.md).
"""

import ml_collections


def get_config() -> ml_collections.ConfigDict:
  config = ml_collections.ConfigDict()
  config.seed = 0
  config.progress_bar = True
  config.objective = 'self_supervised'   # self_supervised (this paper) | triplet (3DFeat-Net)

  config.data = data = ml_collections.ConfigDict()
  data.path = ''             # directory of clouds, Oxford train.txt, or one cloud file
  data.eval_path = ''        # optional held-out clouds for the CF rotation error
  data.format = 'auto'       # .bin layout: auto | xyz | xyzi (KITTI) | xyzn (3DFeat-Net)
  data.crop_radius = 20.0    # metres around the sensor; <= 0 keeps all
  data.num_points = 4096     # N: random subsample (repeats when fewer)
  data.min_points = 64       # fewer after cropping is an error
  data.prefetch = 4          # batches prepared ahead of the jitted step
  data.triplet_axes = 'scene'  # triplet objective: rotate clouds with poses.txt to scene axes
  data.triplet_positives = 'index'  # or 'self': each cloud its own positive (a control)
  # Self-supervised objective: with chance rescan_rate per cloud, its second branch is a
  # re-scan of it by a virtual unit of rescan_sensors (ssd_jax.sensors) standing
  # rescan_shift metres away (datasets.RescanPairDataset), not the same points again.
  # Still one unlabeled cloud per pair; 0 is the paper.
  data.rescan_rate = 0.0
  data.rescan_sensors = ('vlp16', 'hdl32', 'hdl64', 'vls128', 'front120')
  data.rescan_shift = (2.0, 30.0)
  data.rescan_views = 8          # re-scans per cloud (made once, cached)
  # How the unit's beams make the re-scan (ssd_jax.data.rescan.BEAMS): 'select' keeps the
  # cloud's points on its beams, 'cast' casts its rays at the cloud's surfaces (its own rings).
  data.rescan_beams = 'select'
  # Two-view training: with chance pairs_rate per row, the second branch is a real second
  # scan of the place, moved into the first's frame by the transform the miner found
  # (experiments.mine; datasets.MinedPairDataset). `pairs`: the miner's CSV ('' = off,
  # the paper). Still no label: the transform comes from the project's own registration.
  data.pairs = ''
  data.pairs_rate = 0.5
  data.pairs_weight = 'uniform'  # datasets.PAIR_WEIGHTS: each pair alike, or far ones oftener
  data.pairs_links = 1           # >1: also pairs composed of up to this many mined ones

  config.model = model = ml_collections.ConfigDict()
  model.descriptor_dim = 32      # D in {16, 32, 64, 128}
  model.num_clusters = 512       # k cluster centers per cloud
  model.num_samples = 64         # c points per cluster
  model.radius = 2.0             # ball-query radius, metres
  model.center_sampling = 'fps'  # fps (reference) | random
  model.independent_centers = False  # sample the two branches independently
  model.alpha = 1.0              # CF weight temperature (paper)
  model.loss = 'frobenius'       # frobenius (paper) | squared_frobenius (reference code)
  # > 0: add this times an InfoNCE at corresponding cluster centres (within
  # contrastive_radius metres once PC2 is turned back; objective.correspondence_nce).
  model.contrastive_weight = 0.0
  model.contrastive_radius = 1.0
  model.contrastive_temperature = 0.1
  # Which rows the InfoNCE scores (objective.CONTRASTIVE_ROWS): 'all', or 'two_view', only
  # those whose second view is another view of the place (a re-scan, a mined pair).
  model.contrastive_rows = 'all'
  # PC2's cluster centres its points nearest PC1's (turned by R_gt) instead of a sampling
  # of their own, so every centre where the views overlap has its partner (the InfoNCE's
  # positives); off: each branch samples its own (the paper).
  model.partner_centers = False
  # > 0: each partner is PC2's point nearest a random point within this many metres
  # (horizontally) of PC1's turned centre, as far as registration's keypoints of two
  # clouds lie from each other (objective.partner_indices).
  model.partner_jitter = 0.0
  model.self_rotation = 'gaussian'  # gaussian (paper) | uniform (the whole circle)
  model.rotation_sigma = 0.6     # radians
  model.rotation_clip = 1.8        # radians; the reference code clips phi here
  model.orientation_head = 'mlp'  # mlp (3DFeat-Net) | equivariant (turns with the cluster)
  # Branch resampling (label-free; off in the paper): each branch drops up to this
  # share of its points, and keeps the points within branch_crop_radius metres of a
  # sensor offset by up to branch_crop_shift metres (0 = no crop).
  model.branch_dropout = 0.0
  model.branch_crop_shift = 0.0
  model.branch_crop_radius = 20.0
  # Another sensor in one branch (0 = never): with chance branch_sensor_rate a branch keeps
  # only the rings of a sparser spinning unit (beams branch_beam_spacing degrees apart),
  # with chance branch_fov_rate only a horizontal sector of branch_fov degrees.
  model.branch_sensor_rate = 0.0
  model.branch_beam_spacing = (0.7, 2.5)
  model.branch_fov_rate = 0.0
  model.branch_fov = (90.0, 180.0)
  model.jitter_sigma = 0.01      # metres
  model.jitter_clip = 0.05       # metres
  model.bn_momentum = 0.99
  model.use_orientation = True   # False: 3DFeat-Net's descriptor pre-training (no detector)
  model.attention_in_cf = False  # True: the self-supervised detector, w_ij * a_i * b_j in CF
  # Triplet objective only (docs/method.md §5):
  model.margin = 0.2
  # One hinge on the attention-weighted sums (cloud, 3DFeat-Net's released code) or
  # one per anchor cluster (cluster); attention normalised by a softmax (docs/method.md §5)
  # or by its sum (the released code's softplus / sum).
  model.triplet_hinge = 'cloud'              # cloud | cluster
  model.attention_normalization = 'softmax'  # softmax | sum
  model.augmentations = ('jitter', 'rotate_small', 'shift', 'rotate_1d')

  # How the trained network describes keypoints (inference.Model): points per cluster
  # (0: the training value, model.num_samples) and random samplings of each ball whose
  # descriptors are averaged.
  config.inference = inference = ml_collections.ConfigDict()
  inference.num_samples = 0
  inference.draws = 1
  # Metres: the voxel grid of the training clouds, on which registration puts every cloud
  # first (registration.pipeline.to_grid).
  inference.voxel_size = 0.2
  # What registration's default ('auto') farthest-point keypoints are sampled from: 'all'
  # the cloud's points; 'structure', those above its ground (experiments.adapt picks it
  # for a sensor whose mined pairs it registers better).
  inference.keypoints = 'all'

  config.train = train = ml_collections.ConfigDict()
  train.batch_size = 6
  train.learning_rate = 1e-3
  train.lr_schedule = 'constant'   # constant (paper) | cosine (decays to 0 at num_steps)
  train.num_steps = 72_500
  train.log_every = 50
  train.eval_every = 500
  train.checkpoint_every = 2500
  train.keep_checkpoints = 3
  # A finished run whose descriptor weights (and BatchNorm statistics) start this one;
  # the detector is freshly initialised (3DFeat-Net's second stage).
  train.init_from = ''       # a shipped name, export or run to start from
  # What init_from gives: descriptor (3DFeat-Net's stage 2) | model (every weight: fine-tune).
  train.init_scope = 'descriptor'
  return config
