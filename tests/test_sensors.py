"""Sensor presets, re-sampling a cloud to a unit's beams, and the simulated units."""

import numpy as np
import pytest

from ssd_jax import sensors
from ssd_jax.synthetic import lidar, scene as scene_lib


def test_presets_have_their_data_sheet_patterns():
  vlp16 = sensors.get('vlp16').elevations()
  assert len(vlp16) == 16 and vlp16.max() == 15 and vlp16.min() == -15
  np.testing.assert_allclose(np.diff(vlp16), -2.0)
  hdl32 = sensors.get('hdl32').elevations()
  assert len(hdl32) == 32 and abs(np.diff(hdl32).mean() + 1.333) < 0.01
  assert sensors.get('hdl64').num_beams == 64 and sensors.get('vls128').num_beams == 128
  assert sensors.get('front120').horizontal_fov == 120
  with pytest.raises(ValueError, match="unknown sensor 'vlp32'; known: vlp16"):
    sensors.get('vlp32')


def test_resample_keeps_the_points_on_the_units_beams_and_sector():
  rng = np.random.default_rng(0)
  # Points at every elevation and azimuth within 30 m of the sensor.
  n = 20000
  r = rng.uniform(3, 30, n)
  el, az = np.radians(rng.uniform(-20, 20, n)), rng.uniform(-np.pi, np.pi, n)
  pts = np.c_[r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)]
  keep = sensors.resample(pts, sensors.get('vlp16'), width=0.2)
  kept_el = np.degrees(el[keep])
  nearest = np.min(np.abs(kept_el[:, None] - sensors.get('vlp16').elevations()[None]), axis=1)
  assert nearest.max() <= 0.2 + 1e-9
  # 16 bands of 0.4 degrees within 30 degrees of elevation: ~ 16 x 0.4 / 40 of the points.
  assert 0.10 < len(keep) / n < 0.22
  front = sensors.resample(pts, sensors.get('front120'), width=0.2)
  assert np.all(np.abs(np.degrees(az[front])) <= 60) and len(front) > 0


def test_simulated_units_scan_their_rings_and_sector():
  rng = np.random.default_rng(0)
  scene = scene_lib.make_scene(rng, 80.0, 1.0, False)
  caster = lidar.Raycaster(scene)
  pose = np.eye(4)
  pose[:3, 3] = scene.centerline.to_world(np.array([40.0]), np.array([0.0]))[0].tolist() + [
      1.73 + float(scene.ground_height(np.array([40.0]), np.array([0.0]))[0])]
  vlp = lidar.LidarModel.for_sensor('vlp16', beam_elevation_error=0.0, range_noise=0.0,
                                    beam_range_bias=0.0)
  pts, _ = lidar.scan(caster, pose, vlp, rng)
  world = pts.astype(np.float64)   # the sensor frame: elevations from the origin
  el = np.degrees(np.arctan2(world[:, 2], np.linalg.norm(world[:, :2], axis=1)))
  rings = np.unique(np.round(el[np.abs(el) < 14.5]))
  assert len(pts) > 1000 and set(rings) <= set(np.arange(-15, 16, 2).tolist()), rings
  front = lidar.LidarModel.for_sensor('front120')
  pts, _ = lidar.scan(caster, pose, front, rng)
  az = np.degrees(np.arctan2(pts[:, 1], pts[:, 0]))
  assert len(pts) > 1000 and np.abs(az).max() <= 61
  with pytest.raises(ValueError, match='horizontal_fov must be in'):
    lidar.LidarModel(horizontal_fov=0.0)
