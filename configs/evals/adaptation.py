"""Label-free adaptation to a sensor the shipped model never saw, measured: VLP-16 pairs of
scenes the adaptation scans do not show, before (`ours`) and after: `adapted` (the adapt
command's default: pairs mined from the drive, two-view training) and `adapted_single`
(`--pairs=none`: the paper's single-scan objective alone), at equal steps, two seeds each.

Commands (~1.5 hours on 2 CPU cores in all):

    python -m experiments.make_cross_sensor --scans_of=vlp16 --out=data_cache/scans_vlp16 \
        --poses=data_cache/scans_vlp16_poses.txt
    python -m experiments.make_cross_sensor --config=configs/data/vlp16_pairs.py \
        --out=data_cache/vlp16_pairs
    python -m experiments.adapt --scans=data_cache/scans_vlp16 --out=exports/vlp16
    python -m experiments.adapt --scans=data_cache/scans_vlp16 --out=exports/vlp16_single \
        --pairs=none
    # the same two with another seed (the mined pairs reused)
    python -m experiments.adapt --scans=data_cache/scans_vlp16 --out=exports/vlp16_s1 \
        --pairs=exports/vlp16/mined_pairs.csv --config.seed=1
    python -m experiments.adapt --scans=data_cache/scans_vlp16 --out=exports/vlp16_single_s1 \
        --pairs=none --config.seed=1
    python -m experiments.evaluate --config=configs/evals/adaptation.py --workdir=runs/adaptation

(`--poses` only lets `experiments.mine --poses=...` report the mined labels' precision;
nothing in adapt reads it.) Rows: the paper's protocol (ISS, RANSAC over any rotation),
farthest-point keypoints with upright RANSAC (the descriptor alone: RANSAC's best pose),
the bird's-eye-view search alone, and the register command's defaults, for each model's
descriptor. docs/notes/cross_sensor.md has the table.
"""

from ssd_jax.configs.evals import cross_sensor


def get_config():
  config = cross_sensor.get_config()
  del config.evals['real']
  config.evals.synthetic.dataset = 'data_cache/vlp16_pairs/synthetic'
  config.evals.synthetic.title = 'VLP-16 to VLP-16 pairs in unseen scenes'
  config.evals.synthetic.rows = ('iss+ours', 'iss+adapted', 'auto+ours+upright',
                                 'auto+adapted_single+upright', 'auto+adapted_single_s1+upright',
                                 'auto+adapted+upright', 'auto+adapted_s1+upright', 'bev',
                                 'auto+ours+upright+verify+bev',
                                 'auto+adapted+upright+verify+bev')
  config.checkpoints.adapted = 'exports/vlp16'
  config.checkpoints.adapted_single = 'exports/vlp16_single'
  config.checkpoints.adapted_s1 = 'exports/vlp16_s1'
  config.checkpoints.adapted_single_s1 = 'exports/vlp16_single_s1'
  return config
