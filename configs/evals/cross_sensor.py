"""Cross-sensor registration: other LiDARs, 5-40 m apart, any yaw (a sensor x distance
matrix per method).

Command (the sets come first, configs/data/cross_sensor.py):

    python -m experiments.data.make_cross_sensor --out=data_cache/cross_sensor
    python -m experiments.evaluate --config=configs/evals/cross_sensor.py --workdir=runs/cross_sensor

Rows: Open3D's own ISS + FPFH pipeline (`open3d`), the bird's-eye-view search alone,
verified (`bev`); the paper's protocol (ISS, RANSAC over any rotation) and farthest-point
keypoints with upright RANSAC for FPFH and each learned descriptor; the register
command's defaults (`+verify+bev`, its own path) with FPFH, ours, ours_rescan and
ours_mined. Writes WORKDIR/<set>.md and <set>.csv (success, RTE, RRE, inlier ratio per
method x unit x distance). `--config.sampling=uniform`: the upright rows with nearest
neighbours and uniform draws.

Expected (2-core VM, ~28 minutes): the defaults with `ours` register 99.0 % of the 96
real re-scans and 94.2 % of the 120 synthetic pairs (Open3D's pipeline 38.5 / 13.3 %);
docs/notes/cross_sensor.md has every row and cell.
"""

import ml_collections

from ssd_jax.configs.evals import evaluation


def cross_sensor(dataset, distance_bins, title):
  return ml_collections.ConfigDict({
      'type': 'cross_sensor', 'dataset': dataset, 'title': title,
      # Open3D's own pipeline, the BEV search alone, the paper's protocol (ISS, RANSAC over
      # any rotation), farthest-point keypoints with upright RANSAC, and the register
      # command's defaults (RANSAC's and the BEV search's best poses verified).
      'rows': ('open3d', 'bev', 'iss+fpfh', 'iss+ours', 'iss+ours_rescan', 'iss+ours_mined',
               'iss+feat3dnet', 'auto+fpfh+upright', 'auto+ours+upright',
               'auto+ours_rescan+upright', 'auto+ours_mined+upright', 'auto+feat3dnet+upright',
               'auto+fpfh+upright+verify+bev', 'auto+ours+upright+verify+bev',
               'auto+ours_rescan+upright+verify+bev', 'auto+ours_mined+upright+verify+bev'),
      'distance_bins': distance_bins,   # metres; the columns of the matrix
  })


def get_config() -> ml_collections.ConfigDict:
  config = evaluation.get_config()
  config.evals.synthetic = cross_sensor(
      'data_cache/cross_sensor/synthetic', ((5.0, 10.0), (10.0, 20.0), (20.0, 30.0), (30.0, 40.0)),
      'Cross-sensor registration, synthetic streets')
  config.evals.real = cross_sensor(
      'data_cache/cross_sensor/real', ((5.0, 10.0), (10.0, 20.0), (20.0, 30.0)),
      'Cross-sensor registration, real scans re-scanned by other units')
  return config
