"""`ours_mined`: the shipped `ours` fine-tuned, without labels, on pairs of real scans the
project registered itself. An unlabeled drive whose scans take turns among five units
(16-, 32-, 64-, 128-beam and a 120° solid state, `ssd_jax/sensors.py`), a scan every 6 m
through 3 scenes of its own (no test scene), is mined by `experiments.mine` (the classical
path: FPFH, upright RANSAC, the BEV search, verification; kept where confident and a loop
of three closes). Half of each batch's second branches are then the other scan of a kept
pair, 6-48 m away and by another unit, moved into the first by the mined transform; half
the paper's turned copy. As `ours_rescan`, PC2's centres are the partners of PC1's and an
InfoNCE at them joins the rotation loss. Both views of a mined pair come from two
standpoints and two units' rings, where a re-scan (`ours_rescan`) keeps the training
cloud's own points.

Command (the drive, the miner, training, export):

    python -m experiments.make_cross_sensor --scans_of=vlp16,hdl32,hdl64,vls128,front120 \
        --out=data_cache/scans_mixed --poses=data_cache/scans_mixed_poses.txt
    python -m experiments.mine --scans=data_cache/scans_mixed --out=runs/mined_mixed.csv \
        --poses=data_cache/scans_mixed_poses.txt
    python -m experiments.train --config=configs/ours_mined.py --workdir=runs/ours_mined
    python -m experiments.export --run=runs/ours_mined --out=ssd_jax/weights/ours_mined

(`--poses` is read only to report the mined labels' precision: 549 of 649 candidates
kept, every label within 2 m / 5°.) Expected (2-core CPU VM; the drive 0.5 min, mining
~50 min, training ~19 minutes with a second run sharing the cores): the descriptor alone
(farthest-point keypoints, upright RANSAC) on the synthetic cross-sensor test set 70.0 %
(`--config.seed=1`: 66.7 %; `ours_rescan` 67.5 / 60.8 %), validation set 79.2 / 70.8 %
(`ours_rescan` 70.8 / 65.0 %); the model card (ssd_jax/weights/ours_mined/MODEL_CARD.md)
has the real and paper-protocol rows.
"""

from ssd_jax.configs import ours_rescan


def get_config():
  config = ours_rescan.get_config()
  config.data.path = 'data_cache/scans_mixed'
  config.data.pairs = 'runs/mined_mixed.csv'
  config.data.rescan_rate = 0.0
  return config
