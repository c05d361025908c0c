"""Cross-sensor registration: other LiDARs, 5-40 m apart, any yaw (a sensor x distance
matrix per method).

Command (the sets come first, configs/data/cross_sensor.py):

    python -m experiments.make_cross_sensor --out=data_cache/cross_sensor
    python -m experiments.evaluate --config=configs/evals/cross_sensor.py --workdir=runs/cross_sensor

Rows: `open3d`, Open3D's own ISS + FPFH pipeline with the paper's searches
(ssd_jax/registration/reference.py); `bev`, the bird's-eye-view search alone
(ssd_jax/registration/bev.py), its 5 best poses verified; the paper's protocol (ISS
keypoints, RANSAC over any rotation) with FPFH and each learned descriptor; the same
descriptors with farthest-point keypoints and upright RANSAC; FPFH, ours, ours_rescan and
ours_mined with the register command's defaults (the same, RANSAC's 10 best poses and the
BEV search's 5 verified against the clouds).
Writes WORKDIR/<set>.md (summary, one success matrix per method) and <set>.csv (success,
RTE, RRE and inlier ratio per method x unit x distance). docs/notes/cross_sensor.md has the
protocol and every cell.

Expected (2-core AMD EPYC VM, ~28 minutes with every row, the VM alone:
docs/notes/benchmarks.md): real re-scans (96 pairs), defaults + ours 99.0 %, defaults +
FPFH 97.9 %, BEV alone 92.7 %, farthest-point + upright ours 92.7 % / FPFH 81.2 %,
Open3D's pipeline 38.5 % (its RANSAC is not repeatable: +-1 pair), paper protocol ISS +
ours 50.0 %, ISS + FPFH 36.5 %; synthetic (120 pairs), defaults + FPFH 94.2 %, defaults +
ours 94.2 %, BEV alone 93.3 %, farthest-point + upright FPFH 55.8 % / ours 51.7 %, Open3D
13.3 %. `ours_rescan`: farthest-point + upright 93.8 % (real) / 67.5 % (synthetic), ISS
62.5 / 29.2 %, defaults 99.0 / 94.2 %. `ours_mined`: farthest-point + upright 94.8 / 70.0 %
(at least FPFH's in every distance bin), ISS 58.3 / 32.5 %, defaults 99.0 / 94.2 %
(36 minutes with these rows, other evaluations sharing the VM for 10).
`--config.sampling=uniform`: the upright rows with cloud 1's nearest neighbours and
uniform draws (docs/notes/cross_sensor.md).
"""

import ml_collections

from ssd_jax.configs import evaluation


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
