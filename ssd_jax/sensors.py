"""LiDAR sensor models: the beam patterns of common units, and re-sampling a cloud to one.

A spinning unit is a fan of beams at fixed elevations turned about z; a solid-state or
front-facing unit sees only a horizontal sector. The presets follow the data sheets:

    name     like                      beams  vertical field (deg)        azimuth step  horizontal
    vlp16    Velodyne VLP-16 (Puck)       16  +15 ... -15, 2.0 apart     0.2           360
    hdl32    Velodyne HDL-32E             32  +10.67 ... -30.67, 1.33    0.16          360
    hdl64    Velodyne HDL-64E (KITTI)     64  +2 ... -24.33, 1/3 and 1/2 0.17          360
    vls128   Velodyne VLS-128 / OS-128   128  +15 ... -25, ~0.31         0.2           360
    front120 Hesai AT128-like (solid)    128  +12.9 ... -12.5, 0.2       0.1           120 (x fwd)
    os0_64   Ouster OS0-64 (wide field)    64  +45 ... -45, ~1.43         0.35          360

`os0_64` (a short-range robot unit, half of whose beams look up) is the one no shipped
model trained on (`configs/data/os0_pairs.py`). `ssd_jax.synthetic.lidar` casts their rays
into a simulated scene; `resample` keeps the points of a real cloud one of their beams would
have hit from a given standpoint (the cross-sensor real pairs, `ssd_jax.data.rescan`);
`cast` casts the unit's own rays at the surfaces a cloud samples, so its returns lie on the
unit's rings about its own standpoint.
"""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class Sensor:
  """A beam pattern; angles in degrees, distances in metres.

  blocks: (beams, top elevation, bottom elevation) per block of evenly spaced beams.
  """
  name: str
  like: str
  blocks: tuple[tuple[int, float, float], ...]
  azimuth_step: float
  horizontal_fov: float = 360.0
  max_range: float = 80.0

  def elevations(self) -> np.ndarray:
    """Beam elevations [B] degrees, top beam first."""
    return np.concatenate([np.linspace(top, bottom, n) for n, top, bottom in self.blocks])

  @property
  def num_beams(self) -> int:
    return sum(n for n, _, _ in self.blocks)

  def lidar_settings(self) -> dict:
    """The `synthetic.lidar.LidarModel` fields of this pattern (two blocks at most)."""
    if len(self.blocks) > 2:
      raise ValueError(f'{self.name}: the simulator models at most 2 blocks of beams, '
                       f'got {len(self.blocks)}')
    upper, lower = self.blocks[0], self.blocks[1] if len(self.blocks) > 1 else (0, 0.0, 0.0)
    return dict(upper_beams=upper[0], upper_elevation=upper[1:], lower_beams=lower[0],
                lower_elevation=lower[1:], azimuth_step=self.azimuth_step,
                horizontal_fov=self.horizontal_fov, max_range=self.max_range)


SENSORS = {s.name: s for s in (
    Sensor('vlp16', 'Velodyne VLP-16', ((16, 15.0, -15.0),), 0.2, max_range=100.0),
    Sensor('hdl32', 'Velodyne HDL-32E', ((32, 10.67, -30.67),), 0.16, max_range=80.0),
    Sensor('hdl64', 'Velodyne HDL-64E (KITTI)', ((32, 2.0, -8.33), (32, -8.83, -24.33)), 0.17,
           max_range=80.0),
    Sensor('vls128', 'Velodyne VLS-128 / Ouster OS-128', ((128, 15.0, -25.0),), 0.2,
           max_range=100.0),
    Sensor('front120', 'Hesai AT128-like solid state, 120 deg forward',
           ((128, 12.9, -12.5),), 0.1, horizontal_fov=120.0, max_range=80.0),
    Sensor('os0_64', 'Ouster OS0-64, 90 deg vertical field', ((64, 45.0, -45.0),), 0.35,
           max_range=50.0),
)}


def get(name: str) -> Sensor:
  """The preset `name`, or a ValueError listing the presets."""
  if name not in SENSORS:
    raise ValueError(f'unknown sensor {name!r}; known: {", ".join(SENSORS)}')
  return SENSORS[name]


def in_field_of_view(points: np.ndarray, horizontal_fov: float) -> np.ndarray:
  """[N] bool: points [N, 3] (sensor frame, x forward) within +-fov/2 degrees of x."""
  if horizontal_fov >= 360:
    return np.ones(len(points), bool)
  azimuth = np.degrees(np.arctan2(points[:, 1], points[:, 0]))
  return np.abs(azimuth) <= horizontal_fov / 2


def resample(points: np.ndarray, sensor: Sensor, width: float = 0.2) -> np.ndarray:
  """Indices of the points [N, 3] (metres, in the sensor's frame: the sensor at the
  origin, x forward, z up) that `sensor` would return: within `width` degrees of
  elevation of one of its beams, inside its horizontal field of view and range.

  A denser scan seen from the same standpoint becomes the sparser unit's rings; the
  azimuth step is finer than the 0.2 m voxel grid the clouds are put on within tens of
  metres, so it is not imposed.
  """
  points = np.asarray(points, np.float64)
  rng_xy = np.linalg.norm(points[:, :2], axis=1)
  elev = np.degrees(np.arctan2(points[:, 2], rng_xy))
  beams = np.sort(sensor.elevations())
  pos = np.clip(np.searchsorted(beams, elev), 1, len(beams) - 1) if len(beams) > 1 else 0
  nearest = (np.minimum(np.abs(elev - beams[pos - 1]), np.abs(elev - beams[pos]))
             if len(beams) > 1 else np.abs(elev - beams[0]))
  keep = ((nearest <= width) & in_field_of_view(points, sensor.horizontal_fov)
          & (np.linalg.norm(points, axis=1) <= sensor.max_range))
  return np.flatnonzero(keep)


def cast(points: np.ndarray, sensor: Sensor, azimuth_step: float = 0.4,
         max_gap: float = 2.0, depth_tolerance: float = 0.3) -> np.ndarray:
  """What `sensor` at the origin returns from the surfaces that points [N, 3] sample
  (metres, its frame: x forward, z up; those visible from the origin, as
  `data.rescan.visible_from` keeps them): [M, 3] float64 metres, at most one point per ray.

  The rays are the unit's beam elevations at every `azimuth_step` degrees inside its field
  of view. The points are binned into columns of that width by azimuth; a ray meets the
  surface between the column's nearest point above it and nearest point below it (by
  elevation; at most `max_gap` degrees apart; ranges within `depth_tolerance` of each
  other, relative, as a ground seen at a grazing angle changes range fast with
  elevation): the point on the segment between the two at the ray's elevation, moved
  onto the ray. A segment between two points of a plane lies on it, so a flat ground's
  returns lie on it and on this unit's rings about its own standpoint, between the rings
  of the unit that scanned it. `resample` cannot give that: the points it keeps are the
  scan's, on the scanning unit's rings, which two views of one place would then share (a
  pattern a descriptor can match instead of the place). A ray with no such pair (a gap
  wider than `max_gap`, an edge between two depths, the sky) returns nothing.
  """
  points = np.asarray(points, np.float64)
  horizontal = np.linalg.norm(points[:, :2], axis=1)
  ranges = np.linalg.norm(points, axis=1)
  keep = (ranges > 1e-6) & in_field_of_view(points, sensor.horizontal_fov)
  points, horizontal, ranges = points[keep], horizontal[keep], ranges[keep]
  width = min(sensor.horizontal_fov, 360.0)
  columns = int(np.ceil(width / azimuth_step))
  if len(points) == 0:
    return np.zeros((0, 3))
  # One sorted key per point: its column, then its elevation (degrees + 90 < 1000).
  azimuth = np.degrees(np.arctan2(points[:, 1], points[:, 0]))
  column = np.clip(((azimuth + width / 2) // azimuth_step).astype(np.int64), 0, columns - 1)
  elevation = np.degrees(np.arctan2(points[:, 2], horizontal))
  key = column * 1000.0 + elevation + 90.0
  order = np.argsort(key)
  key, points, ranges, elevation = key[order], points[order], ranges[order], elevation[order]
  beams = sensor.elevations()
  ray_column = np.repeat(np.arange(columns), len(beams))
  ray_elevation = np.tile(beams, columns)
  above = np.searchsorted(key, ray_column * 1000.0 + ray_elevation + 90.0)
  below = above - 1
  a, b = np.minimum(above, len(key) - 1), np.maximum(below, 0)
  ok = ((above < len(key)) & (below >= 0) & (key[a] // 1000 == ray_column)
        & (key[b] // 1000 == ray_column) & (elevation[a] - elevation[b] <= max_gap)
        & (np.abs(ranges[a] - ranges[b]) <= depth_tolerance * np.minimum(ranges[a], ranges[b])))
  a, b, ray_column, ray_elevation = a[ok], b[ok], ray_column[ok], ray_elevation[ok]
  share = ((ray_elevation - elevation[b]) / np.maximum(elevation[a] - elevation[b], 1e-9))
  on_segment = points[b] + share[:, None] * (points[a] - points[b])
  ray_azimuth = np.radians((ray_column + 0.5) * azimuth_step - width / 2)
  ray_elevation = np.radians(ray_elevation)
  rays = np.stack([np.cos(ray_elevation) * np.cos(ray_azimuth),
                   np.cos(ray_elevation) * np.sin(ray_azimuth), np.sin(ray_elevation)], -1)
  along = np.einsum('md,md->m', on_segment, rays)
  keep = (along > 0) & (along <= sensor.max_range)
  return rays[keep] * along[keep, None]
