"""`ours_mined`: the shipped `ours` fine-tuned, without labels, on pairs of real scans the
project registered itself. An unlabeled drive whose scans take turns among five units
(16-, 32-, 64-, 128-beam and a 120° solid state, `ssd_jax/sensors.py`), a scan every 6 m
through 3 scenes of its own (no test scene), is mined by `experiments.mine` (the classical
path: FPFH, upright RANSAC, the BEV search, verification; kept where confident and a loop
of three closes). Half of each batch's second branches are then the other scan of a kept
pair, 6-48 m away and by another unit, moved into the first by the mined transform; half
the paper's turned copy. As `ours_rescan`, PC2's centres are the partners of PC1's and an
InfoNCE at them joins the rotation loss.

Command (the drive, the miner, training, export):

    python -m experiments.data.make_cross_sensor --scans_of=vlp16,hdl32,hdl64,vls128,front120 \
        --out=data_cache/scans_mixed --poses=data_cache/scans_mixed_poses.txt
    python -m experiments.mine --scans=data_cache/scans_mixed --out=runs/mined_mixed.csv \
        --poses=data_cache/scans_mixed_poses.txt
    python -m experiments.train --config=configs/training/ours_mined.py --workdir=runs/ours_mined
    python -m experiments.export --run=runs/ours_mined --out=ssd_jax/weights/ours_mined

(`--poses` is read only to report the mined labels' precision.) Expected (2-core CPU VM;
mining ~50 min, training ~19 min): the descriptor alone (farthest-point keypoints,
upright RANSAC) registers 70.0 % of the synthetic cross-sensor test set; the model card
(ssd_jax/weights/ours_mined/MODEL_CARD.md) has every set.
"""

from ssd_jax.configs.training import ours_rescan


def get_config():
  config = ours_rescan.get_config()
  config.data.path = 'data_cache/scans_mixed'
  config.data.pairs = 'runs/mined_mixed.csv'
  config.data.rescan_rate = 0.0
  return config
