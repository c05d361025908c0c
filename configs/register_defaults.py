"""The register command's defaults (farthest-point keypoints, upright RANSAC, its 10 best
poses and the bird's-eye-view search's 5 verified against the clouds), and RANSAC's best
pose alone, on the README's 64-beam sets, beside which the paper's protocol rows were
measured.

Command (after the main job's synthetic set and `experiments.make_real_pairs`; ~40 min):

    python -m experiments.evaluate --config=configs/register_defaults.py \
        --workdir=runs/register_defaults

Expected (2-core CPU VM): with the defaults 100 % on all three sets (KITTI-style 106,
push-broom 53, real re-scans 80) for ours and FPFH (RTE 0.008 / 0.036 / 0.006 m); without
verification, ours 100 / 100 / 100 % and FPFH 99.1 / 100 / 100 %. docs/cross_sensor.md has
the cross-sensor side.
"""

from ssd_jax.configs import evaluation


def get_config():
  config = evaluation.get_config()
  config.rows = ('auto+ours+upright+verify+bev', 'auto+fpfh+upright+verify+bev',
                 'auto+ours+upright', 'auto+fpfh+upright')
  config.evals.kitti = evaluation.registration('data_cache/synthetic_small/test_kitti',
                                               title='KITTI-style synthetic')
  config.evals.oxford = evaluation.registration('data_cache/synthetic_small/test_oxford',
                                                title='Oxford-style push-broom synthetic')
  config.evals.real = evaluation.registration('data_cache/real_pairs', title='Real re-scans')
  return config
