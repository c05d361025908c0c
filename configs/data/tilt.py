"""The tilted test set: cloud 2's unit tilted 10-30 degrees about a random horizontal axis
(a unit mounted pitched or rolled, a robot on a slope), otherwise the pairs of
`configs/data/tilt_upright.py` (same scenes, standpoints and yaws).

Command (~1 minute on 2 CPU cores):

    python -m experiments.data.make_cross_sensor --config=configs/data/tilt.py \
        --out=data_cache/tilt

`configs/evals/tilt.py` evaluates it; the real re-scans tilted the same way are
`make_real_pairs --tilt=10,30`.
"""

from ssd_jax.configs.data import tilt_upright


def get_config():
  config = tilt_upright.get_config()
  config.cross_sensor.tilt = (10.0, 30.0)
  return config
