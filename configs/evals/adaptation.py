"""Label-free adaptation to a sensor `ours` never saw, measured: VLP-16 pairs of
scenes the adaptation scans do not show, before (`ours`) and after: `adapted` (the adapt
command's default: pairs mined from the drive, two-view training with the InfoNCE at
partner centres), `adapted_single` (`--pairs=none`: the scans alone, the same losses) and
`adapted_plain` (the paper's rotation loss alone on the mined pairs), at equal steps.

Commands (~1.5 hours on 2 CPU cores in all):

    python -m experiments.data.make_cross_sensor --scans_of=vlp16 --out=data_cache/scans_vlp16 \
        --poses=data_cache/scans_vlp16_poses.txt
    python -m experiments.data.make_cross_sensor --config=configs/data/vlp16_pairs.py \
        --out=data_cache/vlp16_pairs
    python -m experiments.adapt --scans=data_cache/scans_vlp16 --out=exports/vlp16
    python -m experiments.adapt --scans=data_cache/scans_vlp16 --out=exports/vlp16_s1 \
        --pairs=exports/vlp16/mined_pairs.csv --config.seed=1
    python -m experiments.adapt --scans=data_cache/scans_vlp16 --out=exports/vlp16_single \
        --pairs=none
    # the paper's loss alone, seeds 0 and 1
    python -m experiments.adapt --scans=data_cache/scans_vlp16 --out=exports/vlp16_plain \
        --pairs=exports/vlp16/mined_pairs.csv --config.model.contrastive_weight=0 \
        --config.model.partner_centers=False [--config.seed=1 --out=exports/vlp16_plain_s1]
    python -m experiments.evaluate --config=configs/evals/adaptation.py --workdir=runs/adaptation

The figures were measured from `ours`: `--init=ours` on each adapt command naming no other
(without it, the register command's model, `ours_mined`).
The figures below were measured with every scan mined and no widening: add
`--config.mining.max_scans=210 --config.mining.widen_rounds=0` to the first adapt command.
(`--poses` only lets `experiments.mine --poses=...` report the mined labels' precision;
nothing in adapt reads it.) Rows: the paper's protocol (ISS, RANSAC over any rotation),
farthest-point keypoints with upright RANSAC (the descriptor alone: RANSAC's best pose),
the bird's-eye-view search alone, and the register command's defaults, for each model's
descriptor. Expected, the descriptor alone with `--config.sampling=uniform`: `ours` 38.5 %, adapted 49.0 / 47.9 % (seeds
0 / 1), adapted_single 46.9 %, adapted_plain 46.9 / 44.8 %; docs/notes/cross_sensor.md
has the table. `adaptation_os0.py` measures it on a unit no shipped model saw.
"""

from ssd_jax.configs.evals import cross_sensor


def get_config():
  config = cross_sensor.get_config()
  del config.evals['real']
  config.evals.synthetic.dataset = 'data_cache/vlp16_pairs/synthetic'
  config.evals.synthetic.title = 'VLP-16 to VLP-16 pairs in unseen scenes'
  config.evals.synthetic.rows = ('iss+ours', 'iss+adapted', 'auto+ours+upright',
                                 'auto+adapted_plain+upright', 'auto+adapted_plain_s1+upright',
                                 'auto+adapted_single+upright', 'auto+adapted+upright',
                                 'auto+adapted_s1+upright', 'bev',
                                 'auto+ours+upright+verify+bev',
                                 'auto+adapted+upright+verify+bev')
  config.checkpoints.adapted = 'exports/vlp16'
  config.checkpoints.adapted_s1 = 'exports/vlp16_s1'
  config.checkpoints.adapted_single = 'exports/vlp16_single'
  config.checkpoints.adapted_plain = 'exports/vlp16_plain'
  config.checkpoints.adapted_plain_s1 = 'exports/vlp16_plain_s1'
  return config
