"""Tilted sensors: the descriptor alone and the register command's defaults on pairs whose
second unit is tilted 10-30 degrees, beside the upright pairs of the same scenes, with
each scan levelled by its ground first (`level='ground'`, as `register --level=ground`).

Commands (data ~3 minutes, the evaluation ~15 minutes on 2 CPU cores):

    python -m experiments.data.make_cross_sensor --config=configs/data/tilt_upright.py \
        --out=data_cache/tilt_upright
    python -m experiments.data.make_cross_sensor --config=configs/data/tilt.py --out=data_cache/tilt
    python -m experiments.data.make_real_pairs --real=../shared/data --out=data_cache/real_pairs
    python -m experiments.data.make_real_pairs --real=../shared/data --tilt=10,30 \
        --out=data_cache/real_pairs_tilted
    python -m experiments.evaluate --config=configs/evals/tilt.py --workdir=runs/tilt

Rows: farthest-point keypoints with `ours` and upright RANSAC's best pose (the descriptor
alone), and the register command's defaults (`auto+ours+upright+verify+bev`).
`--config.level=none` evaluates the scans as given. docs/registration.md has the results.
"""

from ssd_jax.configs.evals import evaluation


def get_config():
  config = evaluation.get_config()
  config.level = 'ground'
  config.rows = ('auto+ours+upright', 'auto+ours+upright+verify+bev')
  config.evals.synthetic_upright = evaluation.registration(
      'data_cache/tilt_upright/synthetic', title='Synthetic pairs, upright')
  config.evals.synthetic_tilted = evaluation.registration(
      'data_cache/tilt/synthetic', title='Synthetic pairs, unit 2 tilted 10-30 degrees')
  config.evals.real_upright = evaluation.registration(
      'data_cache/real_pairs', title='Real re-scans, upright')
  config.evals.real_tilted = evaluation.registration(
      'data_cache/real_pairs_tilted', title='Real re-scans, unit 2 tilted 10-30 degrees')
  return config
