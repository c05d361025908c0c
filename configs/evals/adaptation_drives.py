"""Label-free adaptation to a solid-state drive, measured on that drive's own far pairs:
the Livox Avia drive HKU_MB (`configs/evals/real_drives.py` makes its 80 pairs, 0-30 m
apart, as driven and turned) registered by the register command's defaults and by the
descriptor alone, with `ours` and with `ours` adapted to the drive's 457 unlabeled scans
(`experiments.adapt`: mined pairs, then widened by the adapted model; no pose is read).

Commands (the adaptation ~30 minutes on 2 CPU cores, each evaluation ~5):

    python -m experiments.adapt --scans=data_cache/drives/hku_mb/Scans \
        --out=exports/hku_mb_widened
    python -m experiments.evaluate --config=configs/evals/adaptation_livox.py \
        --workdir=runs/adaptation_livox/ours
    python -m experiments.evaluate --config=configs/evals/adaptation_livox.py \
        --config.checkpoints.ours=exports/hku_mb_widened --workdir=runs/adaptation_livox/adapted

(`--config.mining.widen_rounds=0` adapts without the widening, at equal steps.) The rows
are named `ours`: the second command describes with the adapted weights in their place.
Expected (2-core VM): the defaults register 60.0 % of the 80 pairs adapted, 53.8 % with
`ours`, and 8 of the 16 pairs 10-20 m apart against 6 (the adapted export's keypoints on
the structure); docs/notes/real_drives.md has the table.
"""

from ssd_jax.configs.evals import real_drives


def get_config():
  config = real_drives.get_config()
  del config.evals['drives'], config.evals['riverside']
  config.evals.livox.rows = ('register', 'register_descriptor')
  return config
