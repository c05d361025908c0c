"""The upright twin of the tilted test set (`configs/data/tilt.py`): the same scenes, pairs,
distances and yaws, every unit level.

Command (~1 minute on 2 CPU cores):

    python -m experiments.data.make_cross_sensor --config=configs/data/tilt_upright.py \
        --out=data_cache/tilt_upright

48 pairs: 2 unseen scenes x 3 units (HDL-64E, HDL-32E, VLS-128 against the reference
HDL-64E) x 2 distance bins (5-10, 10-20 m) x 4 pairs, any relative yaw.
`configs/evals/tilt.py` evaluates it beside the tilted set.
"""

from ssd_jax.configs.data import cross_sensor as cross_sensor_data


def get_config():
  config = cross_sensor_data.get_config()
  cs = config.cross_sensor
  cs.sensors = ('hdl64', 'hdl32', 'vls128')
  cs.distance_bins = ((5.0, 10.0), (10.0, 20.0))
  cs.pairs_per_cell = 4
  cs.tilt = (0.0, 0.0)    # degrees: cloud 2's unit tilted by an angle in this range
  config.real.sources = ()
  return config
