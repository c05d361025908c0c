"""Label-free adaptation to a unit no shipped model trained on: 96 OS0-64 pairs
(`ssd_jax/sensors.py` `os0_64`: 64 beams over +-45 deg, 50 m) 5-40 m apart in 4 scenes
the adaptation scans do not show, before (`ours`, and the other shipped models) and after
`experiments.adapt` on 210 unlabeled OS0-64 scans of 3 scenes of their own.

Commands (~1.5 hours on 2 CPU cores in all; the figures of the notes were measured with
every scan mined and no widening: add `--config.mining.max_scans=210
--config.mining.widen_rounds=0` to the first adapt command):

    python -m experiments.data.make_cross_sensor --scans_of=os0_64 --out=data_cache/scans_os0 \
        --poses=data_cache/scans_os0_poses.txt
    python -m experiments.data.make_cross_sensor --config=configs/data/os0_pairs.py \
        --out=data_cache/os0_pairs
    python -m experiments.adapt --scans=data_cache/scans_os0 --out=exports/os0
    python -m experiments.adapt --scans=data_cache/scans_os0 --out=exports/os0_from_mined \
        --init=ours_mined --pairs=exports/os0/mined_pairs.csv
    python -m experiments.adapt --scans=data_cache/scans_os0 --out=exports/os0_rate1 \
        --pairs=exports/os0/mined_pairs.csv --config.data.pairs_rate=1.0
    python -m experiments.evaluate --config=configs/evals/adaptation_os0.py \
        --workdir=runs/adaptation_os0

The figures were measured from `ours`: `--init=ours` on each adapt command naming no other
(without it, the register command's model, `ours_mined`).
Rows: the descriptor alone (upright RANSAC's best pose) from farthest-point keypoints of
all points (`auto+`) or of the structure above the ground (`structure+`, where the
adapted model's keypoints lie) for FPFH, each shipped model and each adapted one; the
bird's-eye-view search alone; the register command's defaults with `ours` and adapted.
Expected: the descriptor alone 55.2 % with `ours`, 70.8 % adapted (from the structure,
its own keypoints); docs/notes/cross_sensor.md has the table and the times.
"""

from ssd_jax.configs.evals import cross_sensor


def get_config():
  config = cross_sensor.get_config()
  del config.evals['real']
  config.evals.synthetic.dataset = 'data_cache/os0_pairs/synthetic'
  config.evals.synthetic.title = 'OS0-64 to OS0-64 pairs in unseen scenes'
  config.evals.synthetic.rows = ('auto+fpfh+upright', 'structure+fpfh+upright',
                                 'auto+ours+upright', 'structure+ours+upright',
                                 'auto+ours_rescan+upright', 'auto+ours_mined+upright',
                                 'auto+adapted+upright', 'structure+adapted+upright',
                                 'auto+adapted_rate1+upright',
                                 'auto+adapted_from_mined+upright',
                                 'bev', 'auto+ours+upright+verify+bev',
                                 'structure+adapted+upright+verify+bev')
  config.checkpoints.adapted = 'exports/os0'
  config.checkpoints.adapted_rate1 = 'exports/os0_rate1'
  config.checkpoints.adapted_from_mined = 'exports/os0_from_mined'
  return config
