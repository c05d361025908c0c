"""Label-free adaptation to a sensor the shipped model never saw, measured: VLP-16 pairs of
scenes the adaptation scans do not show, before (`ours`) and after (`adapted`).

Commands (~25 minutes on 2 CPU cores in all):

    python -m experiments.make_cross_sensor --scans_of=vlp16 --out=data_cache/scans_vlp16
    python -m experiments.make_cross_sensor --config=configs/data/vlp16_pairs.py \
        --out=data_cache/vlp16_pairs
    python -m experiments.adapt --scans=data_cache/scans_vlp16 --out=exports/vlp16
    python -m experiments.evaluate --config=configs/evals/adaptation.py --workdir=runs/adaptation

Rows: the paper's protocol (ISS, RANSAC over any rotation), farthest-point keypoints with
upright RANSAC (RANSAC's best pose alone), the bird's-eye-view search alone, and the
register command's defaults (RANSAC's 10 and the BEV search's 5 best poses verified), for
each model's descriptor. Expected (2-core CPU VM, 48 pairs, ~10 min): farthest-point +
upright 41.7 % with `ours`, 47.9 % adapted; paper protocol 10.4 -> 16.7 %; BEV search alone
79.2 %; defaults 77.1 % with `ours`, 75.0 % adapted. docs/notes/cross_sensor.md has the table.
"""

from ssd_jax.configs.evals import cross_sensor


def get_config():
  config = cross_sensor.get_config()
  del config.evals['real']
  config.evals.synthetic.dataset = 'data_cache/vlp16_pairs/synthetic'
  config.evals.synthetic.title = 'VLP-16 to VLP-16 pairs in unseen scenes'
  config.evals.synthetic.rows = ('iss+ours', 'iss+adapted', 'auto+ours+upright',
                                 'auto+adapted+upright', 'bev', 'auto+ours+upright+verify+bev',
                                 'auto+adapted+upright+verify+bev')
  config.checkpoints.adapted = 'exports/vlp16'
  return config
