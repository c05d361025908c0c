"""The register command's defaults (farthest-point keypoints, 512 then 1,024 where those
leave the pose in doubt, upright RANSAC, its 10 best poses and the bird's-eye-view
search's 5 verified against the clouds) with FPFH and the shipped `ours`, `ours_rescan`
and `ours_mined`, on the README's 64-beam sets, each row through the command's own path
(`pipeline.Registrar` on the files): the README's "defaults" rows.

Command (after the main job's synthetic set and `experiments.data.make_real_pairs`; 10 min
on the 2-core AMD EPYC VM with the test suite sharing it, FPFH most of it):

    python -m experiments.evaluate --config=configs/evals/register_defaults.py \
        --workdir=runs/register_defaults

Expected (2-core CPU VM): 100 % on all three sets (KITTI-style 106, push-broom 53, real
re-scans 80) with every row, RTE 0.004 / 0.033 / 0.005 m, every pair ended at the coarse
level, trusted and polished; docs/notes/results.md has the table and RANSAC's best pose
alone.
"""

from ssd_jax.configs.evals import evaluation


def get_config():
  config = evaluation.get_config()
  config.rows = ('auto+ours+upright+verify+bev', 'auto+ours_rescan+upright+verify+bev',
                 'auto+ours_mined+upright+verify+bev', 'auto+fpfh+upright+verify+bev')
  config.evals.kitti = evaluation.registration('data_cache/synthetic_small/test_kitti',
                                               title='KITTI-style synthetic')
  config.evals.oxford = evaluation.registration('data_cache/synthetic_small/test_oxford',
                                                title='Oxford-style push-broom synthetic')
  config.evals.real = evaluation.registration('data_cache/real_pairs', title='Real re-scans')
  return config
