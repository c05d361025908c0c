"""A VLP-16 against VLP-16 test set: the sensor the shipped models never trained on, in
scenes the adaptation scans do not show (`experiments.adapt`'s measurement).

Command (~1 minute):

    python -m experiments.data.make_cross_sensor --config=configs/data/vlp16_pairs.py \
        --out=data_cache/vlp16_pairs

96 pairs (4 scenes x 4 distance bins x 6 pairs), both clouds from a VLP-16-like unit
5-40 m apart at any yaw; no real re-scans. (With 48 pairs, two adapted models one seed
apart differed by 8 points: a pair is 1 point here.) `configs/evals/adaptation.py` evaluates it.
"""

from ssd_jax.configs.data import cross_sensor as cross_sensor_data


def get_config():
  return cross_sensor_data.one_unit('vlp16')
