"""The cross-sensor test sets: other LiDARs, farther apart, any relative yaw.

Command (~1-2 minutes on 2 CPU cores):

    python -m experiments.data.make_cross_sensor --config=configs/data/cross_sensor.py \
        --out=data_cache/cross_sensor

Writes OUT/synthetic (simulated streets scanned by the reference HDL-64E and by each unit
of `cross_sensor.sensors` 5-40 m away; 2 unseen scenes x 5 units x 4 distance bins x 3
pairs = 120 pairs) and OUT/real (each real scan beside the project paired with a re-scan
of it by each unit from a virtual standpoint 5-30 m away; 8 KITTI scans x 4 units x 3 bins =
96 pairs, when ../shared/data or SSD_JAX_SHARED_DATA is there). `configs/evals/cross_sensor.py`
evaluates them; docs/notes/cross_sensor.md has the protocol and the results.
"""

import ml_collections

from ssd_jax.configs.data import synthetic


def get_config():
  config = synthetic.get_config()
  config.cross_sensor = cs = ml_collections.ConfigDict()
  cs.reference = 'hdl64'             # cloud 1 of every pair (ssd_jax/sensors.py)
  cs.sensors = ('vlp16', 'hdl32', 'hdl64', 'vls128', 'front120')   # cloud 2
  cs.distance_bins = ((5.0, 10.0), (10.0, 20.0), (20.0, 30.0), (30.0, 40.0))   # metres
  cs.num_scenes = 2
  cs.pairs_per_cell = 3              # per scene, sensor and distance bin

  # Re-scans of the real scans (ssd_jax/data/rescan.py): the second view keeps what the
  # unit would return from a standpoint at the bin's distance, turned by any yaw.
  config.real = real = ml_collections.ConfigDict()
  # Single KITTI scans in their sensor's frame (the Oxford models are accumulated submaps:
  # no sensor to re-scan from).
  real.sources = ('example/kitti_*.bin', 'kitti_object_velodyne/*.bin')   # under --real
  real.sensors = ('vlp16', 'hdl32', 'vls128', 'front120')
  real.distance_bins = ((5.0, 10.0), (10.0, 20.0), (20.0, 30.0))
  real.pairs_per_cell = 1            # per scan, sensor and distance bin
  real.max_range = 40.0              # both views keep what lies within this of their sensor
  return config


def one_unit(unit: str) -> ml_collections.ConfigDict:
  """A set of one unit's pairs (both clouds from `unit`, ssd_jax/sensors.py): 96 pairs,
  4 scenes x 4 distance bins x 6 pairs, no real re-scans (the adaptation's measurement)."""
  config = get_config()
  config.cross_sensor.reference = unit
  config.cross_sensor.sensors = (unit,)
  config.cross_sensor.pairs_per_cell = 6
  config.cross_sensor.num_scenes = 4
  config.real.sources = ()
  return config
