"""The default synthetic dataset: street scenes scanned by a simulated HDL-64E.

Command:

    python -m experiments.data.make_synthetic --config=configs/data/synthetic.py --out=data_cache/synthetic

Writes 12 training scenes (~1,100 clouds with a 3DFeat-Net `train.txt`), 4
KITTI-style test scenes (~170 clouds, ~200 pairs), 4 Oxford-style test scenes
(push-broom submaps: 121 models, 108 pairs) and 2,000 descriptor-matching cluster
pairs, in ~15 minutes on 2 CPU cores (~0.3 s per scan; the FPFH-free part). See
`ssd_jax/synthetic/dataset.py` for the layout.
"""

import ml_collections


def get_config() -> ml_collections.ConfigDict:
  config = ml_collections.ConfigDict()
  config.seed = 0
  config.scene_length = 240.0     # metres of street per scene
  config.voxel_size = 0.2         # metres; 3DFeat-Net's processing
  config.normal_radius = 1.0      # metres, up to 30 neighbours

  # What the streets hold beyond their layout (ssd_jax/synthetic/scene.py, make_scene).
  config.scene = scene = ml_collections.ConfigDict()
  scene.clutter_scale = 1.0         # times the drawn density of sidewalk objects
  scene.varied_objects = False      # eight kinds of object at random yaws, angled cars

  # Velodyne HDL-64E-like scanner (angles in degrees, distances in metres).
  config.lidar = lidar = ml_collections.ConfigDict()
  lidar.upper_beams = 32
  lidar.upper_elevation = (2.0, -8.33)
  lidar.lower_beams = 32
  lidar.lower_elevation = (-8.83, -24.33)
  lidar.azimuth_step = 0.17
  lidar.min_range = 2.5
  lidar.max_range = 80.0            # real KITTI scans end at 79.9 m
  lidar.range_noise = 0.02
  lidar.beam_range_bias = 0.03      # fixed per-beam calibration errors
  lidar.beam_elevation_error = 0.05
  lidar.dropout = 0.05
  lidar.mount_height = 1.73

  # Oxford-like training folder: positives / non-negatives by sensor distance.
  config.train = train = ml_collections.ConfigDict()
  train.num_scenes = 12
  train.spacing = 4.0              # metres of travel between scans
  train.positive_radius = 10.0
  train.non_negative_radius = 50.0

  # KITTI-style test set (docs/method.md §6): a cloud every ~10 m, pairs < 10 m apart.
  config.test_kitti = kitti = ml_collections.ConfigDict()
  kitti.num_scenes = 4
  kitti.spacing = 10.0
  kitti.spacing_jitter = 0.25      # each cloud moves up to ±2.5 m along the lane
  kitti.pair_max_distance = 10.0
  kitti.random_yaw = False         # True: turn each scan about z (configs/data/synthetic_kitti_yaw.py)

  # Oxford-style test models: 60 m submaps (2 x crop_radius), 16,384 points, random
  # rotation about z.
  config.test_oxford = oxford = ml_collections.ConfigDict()
  oxford.num_scenes = 4
  oxford.spacing = 10.0
  oxford.spacing_jitter = 0.25
  oxford.pair_max_distance = 10.0
  oxford.crop_radius = 30.0
  oxford.num_points = 16384
  # The largest grid <= this (5 % steps) giving >= num_points distinct points in the crop,
  # then a random subset: real models have a near-regular 0.2 m spacing and no repeats.
  oxford.voxel_size = 0.2
  # 'pushbroom' (default): a 2D line scanner's lines accumulated over 2 crop_radius metres
  # of one pass, every line_spacing metres (ssd_jax/synthetic/pushbroom.py), as RobotCar's
  # test models were made. 'spinning': one HDL-64 scan cropped to crop_radius (the spinning
  # Oxford-style set of docs/notes/results.md; docs/synthetic_data.md).
  oxford.sensor = 'pushbroom'
  oxford.line_spacing = 0.2

  # Descriptor-matching cluster pairs (docs/method.md §4).
  config.clusters = clusters = ml_collections.ConfigDict()
  clusters.num_scenes = 2
  clusters.spacing = 5.0
  clusters.num_pairs = 30_000     # the paper's count
  clusters.radius = 4.0
  # 'random': centres at random scan points, as the paper's 30,000 pairs (docs/method.md §4,
  # which its ISS-filtered variant then thins out); 'iss': centres at ISS keypoints.
  clusters.centers = 'random'
  clusters.positive_max_distance = 10.0
  clusters.negative_min_distance = 20.0
  clusters.max_surface_distance = 0.2   # a matching centre must lie on the other scan
  clusters.min_points = 64
  return config
