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
  os0 = sensors.get('os0_64')
  assert os0.num_beams == 64 and os0.elevations().max() == 45 and os0.elevations().min() == -45
  assert os0.max_range == 50
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


def _ground_rings(sensor_name: str, height: float, max_range: float = 40.0) -> np.ndarray:
  """A flat ground at z = -height as `sensor_name` at the origin samples it: [N, 3]."""
  sensor = sensors.get(sensor_name)
  el = np.radians(sensor.elevations())
  el = el[np.tan(-el) * max_range > height]   # the beams that meet the ground in range
  az = np.radians(np.arange(-180, 180, 0.2))
  r = height / np.tan(-el)[:, None]
  return np.stack(np.broadcast_arrays(r * np.cos(az), r * np.sin(az),
                                      np.full((len(el), 1), -height)), -1).reshape(-1, 3)


def test_cast_puts_the_grounds_returns_on_the_new_units_rings():
  # The ground as an HDL-64 at the origin samples it, seen by a VLP-16 8 m away: the
  # returns lie on the ground and on the VLP-16's beams about its own standpoint.
  ground = _ground_rings('hdl64', 1.73)
  standpoint = np.array([8.0, 3.0, 0.0])
  out = sensors.cast(ground - standpoint, sensors.get('vlp16'))
  assert np.abs(out[:, 2] + 1.73).max() < 0.01     # on the ground: a segment of a plane
  el = np.degrees(np.arctan2(out[:, 2], np.linalg.norm(out[:, :2], axis=1)))
  assert np.min(np.abs(el[:, None] - sensors.get('vlp16').elevations()), axis=1).max() < 1e-6
  # Most of the VLP-16's rings within the HDL-64's 40 m: one return per ray (0.4 degrees).
  ideal = _ground_rings('vlp16', 1.73) + standpoint
  assert len(out) > 0.7 * np.sum(np.linalg.norm(ideal[:, :2], axis=1) < 40) / 2
  # Its returns lie between the HDL-64's rings as a VLP-16's would (within 5 cm of one of
  # their radii about the HDL-64: 26 % of them; the VLP-16's true rings: 16 %), where every
  # point resample keeps lies on one: it keeps the scan's points.
  radii = np.unique(np.round(np.linalg.norm(ground[:, :2], axis=1), 6))
  def on_old_rings(local):
    r = np.linalg.norm((local + standpoint)[:, :2], axis=1)
    return np.mean(np.min(np.abs(r[:, None] - radii[None]), axis=1) < 0.05)
  kept = (ground - standpoint)[sensors.resample(ground - standpoint, sensors.get('vlp16'))]
  assert on_old_rings(kept) == 1.0 and on_old_rings(out) < 0.4


def test_cast_returns_the_front_surface_and_nothing_across_an_edge():
  # A wall 10 m ahead (x = 10, |y| < 2, |z| < 0.5) in front of one at 20 m (|y| < 8,
  # |z| < 1), both sampled every 5 cm, without the far wall's points the near one hides.
  y, z = np.meshgrid(np.arange(-8, 8.01, 0.05), np.arange(-1, 1.01, 0.05))
  back = np.c_[np.full(y.size, 20.0), y.ravel(), z.ravel()]
  hidden = (np.abs(back[:, 1]) < 4) & (np.abs(back[:, 2]) <= 1)
  front, back = back[hidden] * 0.5, back[~hidden]
  out = sensors.cast(np.r_[front, back], sensors.get('vls128'))
  near = np.abs(out[:, 0] - 10.0) < 0.05   # within a 0.4 degree column of the ray
  far = np.abs(out[:, 0] - 20.0) < 0.05
  assert near.sum() > 500 and far.sum() > 500 and np.all(near | far)   # no return between
  az = np.degrees(np.arctan2(out[:, 1], out[:, 0]))
  assert np.all(np.abs(az[near]) < 11.4) and not np.any(far & (np.abs(az) < 11.0)
                                                        & (np.abs(out[:, 2]) < 0.9))
  assert sensors.cast(np.zeros((0, 3)), sensors.get('vlp16')).shape == (0, 3)
