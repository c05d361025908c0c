"""Label-free adaptation to a real drive, measured on that drive's own far pairs: the Livox
Avia drive HKU_MB (80 pairs) and the OS1-64 Riverside02 run (128 pairs), 0-30 m apart, as
driven and turned (`configs/evals/real_drives.py` makes both sets), registered by the
register command's defaults and by the descriptor alone, with its model
(`pretrained.DEFAULT`, `ours_mined`) and with that model adapted to the drive's unlabeled
scans (`experiments.adapt`: mined pairs, then widened by the adapted model; no pose is read).

Commands (each adaptation ~20-30 minutes on 2 CPU cores, each evaluation ~5):

    python -m experiments.adapt --scans=data_cache/drives/hku_mb/Scans --out=exports/hku_mb
    python -m experiments.adapt --scans=PATH/TO/new_Riverside02_bag_281/Scans \
        --out=exports/riverside02
    python -m experiments.evaluate --config=configs/evals/adaptation_drives.py \
        --workdir=runs/adaptation_drives/default
    python -m experiments.evaluate --config=configs/evals/adaptation_drives.py \
        --config.checkpoints.ours_mined=exports/hku_mb --workdir=runs/adaptation_drives/hku_mb

(and so for exports/riverside02). The rows are named after the default model: the
evaluation describes with the adapted weights in their place (an export keeps its own
keypoint domain). `--init=ours` adapts `ours` instead, `--config.checkpoints.ours_mined=ours`
measures it; `--config.mining.widen_rounds=0` adapts without the widening, at equal steps.
Expected (2-core VM), defaults at 10-20 m, adapted against the default model: HKU_MB
87.5 % against 87.5 % (the descriptor alone 25.0 % against 25.0 %; all pairs 73.8 against
73.8 %, the descriptor alone 50.0 against 43.8 %); Riverside02, measured before the retries
of refused poses, 100.0 % against 93.8 % (84.4 % against 68.8 %);
docs/notes/real_drives.md has the tables (and HKU_MB's 240 pairs: 68.8 against 70.8 %).
"""

from ssd_jax.configs.evals import real_drives


def get_config():
  config = real_drives.get_config()
  del config.evals['drives']
  for name in ('livox', 'riverside'):
    config.evals[name].rows = ('register', 'register_descriptor')
  return config
