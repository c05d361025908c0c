"""An OS0-64 against OS0-64 test set: a unit in no shipped model's training data (`ours`
trained on 64-beam scans, `ours_rescan` and `ours_mined` on the other five units of
`ssd_jax/sensors.py`), in scenes the adaptation scans do not show (`experiments.adapt`'s
measurement, `configs/evals/adaptation_os0.py`).

Command (~1 minute):

    python -m experiments.data.make_cross_sensor --config=configs/data/os0_pairs.py \
        --out=data_cache/os0_pairs

96 pairs (4 scenes x 4 distance bins x 6 pairs), both clouds from the wide-field 64-beam
unit 5-40 m apart at any yaw; no real re-scans.
"""

from ssd_jax.configs.data import cross_sensor as cross_sensor_data


def get_config():
  return cross_sensor_data.one_unit('os0_64')
