"""Label-free adaptation to a unit no shipped model trained on, measured: 96 OS0-64 pairs
(`ssd_jax/sensors.py` `os0_64`: 64 beams over +-45 deg, 50 m) 5-40 m apart in 4 scenes
the adaptation scans do not show, before (`ours`, and the other shipped models) and after
`experiments.adapt` on 210 unlabeled OS0-64 scans of 3 scenes of their own.

Commands (~1.5 hours on 2 CPU cores in all):

    python -m experiments.make_cross_sensor --scans_of=os0_64 --out=data_cache/scans_os0 \
        --poses=data_cache/scans_os0_poses.txt
    python -m experiments.make_cross_sensor --config=configs/data/os0_pairs.py \
        --out=data_cache/os0_pairs
    python -m experiments.adapt --scans=data_cache/scans_os0 --out=exports/os0
    python -m experiments.adapt --scans=data_cache/scans_os0 --out=exports/os0_from_mined \
        --init=ours_mined --pairs=exports/os0/mined_pairs.csv
    python -m experiments.adapt --scans=data_cache/scans_os0 --out=exports/os0_rate1 \
        --pairs=exports/os0/mined_pairs.csv --config.data.pairs_rate=1.0
    python -m experiments.evaluate --config=configs/evals/adaptation_os0.py \
        --workdir=runs/adaptation_os0

The figures below were measured with every scan mined and no widening: add
`--config.mining.max_scans=210 --config.mining.widen_rounds=0` to the first adapt command.
(`--poses` only lets `experiments.mine --poses=...` report the mined labels' precision:
554 of 649 candidates kept, every label within 2 m / 5 deg, median 0.022 m / 0.16 deg.)
Rows: the descriptor alone (upright RANSAC's best pose) from farthest-point keypoints of
all points (`auto+`) or of the structure above the ground (`structure+`: where the
adapted model's own keypoints lie, as the adapt command chose: 16 of 32 chained mined
pairs against 4) for FPFH, each shipped model and each adapted one, the bird's-eye-view
search alone, and the register command's defaults with `ours` and adapted. Expected, the
descriptor alone: FPFH 51.0 % (structure 56.2), `ours` 55.2 % (structure 63.5),
`ours_rescan` 55.2 %, `ours_mined` 57.3 %; adapted from all points 56.2 %, **from the
structure, its own keypoints, 70.8 %** (every second branch a mined pair: 57.3 %; from
`ours_mined` 59.4 %, both from all points); the BEV search alone 74.0 %, the defaults with
`ours` 74.0 %, adapted 76.0 % (22 minutes on 2 CPU cores for these rows, the models made,
a test run sharing the cores). docs/notes/cross_sensor.md has the table.
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
