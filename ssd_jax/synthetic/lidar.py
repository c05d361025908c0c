"""A spinning multi-beam LiDAR simulated with Open3D ray casting.

The default model follows KITTI's Velodyne HDL-64E: 64 beams in two blocks
(+2.0° … −8.33° at ~1/3° and −8.83° … −24.33° at ~1/2°), 0.17° azimuth steps
(10 Hz), returns from 2.5 m to 80 m (the real KITTI scans beside the project
all end at 79.9 m), 2 cm range noise and random dropout, plus a fixed per-beam
calibration error (range bias, elevation offset) per sensor, which is what
makes real ground rings look thick.
Materials change the returns: glass drops most of them and foliage scatters
them along the ray. Grazing incidence and long range drop returns more often,
as real sensors do. Points come back in the sensor frame (x forward, y left,
z up), like KITTI's velodyne files. `LidarModel.for_sensor` builds the other units of
`ssd_jax.sensors` (16-, 32-, 128-beam spinning, a 120-degree solid-state unit).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ssd_jax import sensors
from ssd_jax.synthetic.scene import Label, Scene


def check_sensor_fields(model, rates: tuple[str, ...], nonnegative: tuple[str, ...]) -> None:
  """The checks every simulated sensor shares: 0 <= min_range < max_range (metres), the
  `rates` fields in [0, 1), the `nonnegative` ones >= 0. Raises ValueError naming the field."""
  if not 0 <= model.min_range < model.max_range:
    raise ValueError(f'need 0 <= min_range < max_range, got {model.min_range}, {model.max_range}')
  for name in rates:
    if not 0 <= getattr(model, name) < 1:
      raise ValueError(f'{name} must be in [0, 1), got {getattr(model, name)}')
  for name in nonnegative:
    if getattr(model, name) < 0:
      raise ValueError(f'{name} must be >= 0, got {getattr(model, name)}')


@dataclasses.dataclass(frozen=True)
class LidarModel:
  """Scanner parameters; angles in degrees, distances in metres."""
  upper_beams: int = 32
  upper_elevation: tuple[float, float] = (2.0, -8.33)
  lower_beams: int = 32
  lower_elevation: tuple[float, float] = (-8.83, -24.33)
  azimuth_step: float = 0.17
  min_range: float = 2.5
  max_range: float = 80.0
  range_noise: float = 0.02
  beam_range_bias: float = 0.03       # metres, std of the fixed per-beam offset
  beam_elevation_error: float = 0.05  # degrees, std of the fixed per-beam offset
  dropout: float = 0.05
  glass_dropout: float = 0.8
  foliage_dropout: float = 0.3
  foliage_scatter: float = 0.3
  mount_height: float = 1.73
  horizontal_fov: float = 360.0      # degrees around x (forward); < 360: a sector

  def __post_init__(self):
    if self.upper_beams < 0 or self.lower_beams < 0 or self.num_beams < 1:
      raise ValueError(f'need at least one beam, got upper_beams={self.upper_beams}, '
                       f'lower_beams={self.lower_beams}')
    if not 0 < self.azimuth_step <= 45:
      raise ValueError(f'azimuth_step must be in (0, 45] degrees, got {self.azimuth_step}')
    if not 0 < self.horizontal_fov <= 360:
      raise ValueError(f'horizontal_fov must be in (0, 360] degrees, got {self.horizontal_fov}')
    check_sensor_fields(self, ('dropout', 'glass_dropout', 'foliage_dropout'),
                        ('range_noise', 'beam_range_bias', 'beam_elevation_error',
                         'foliage_scatter'))

  @classmethod
  def from_config(cls, config) -> 'LidarModel':
    """From a ConfigDict / mapping with any subset of the field names."""
    fields = {f.name for f in dataclasses.fields(cls)}
    values = {k: (tuple(v) if isinstance(v, (list, tuple)) else v)
              for k, v in dict(config).items() if k in fields}
    unknown = set(dict(config)) - fields
    if unknown:
      raise ValueError(f'unknown LiDAR settings {sorted(unknown)}; known: {sorted(fields)}')
    return cls(**values)

  @classmethod
  def for_sensor(cls, name: str, **overrides) -> 'LidarModel':
    """The beam pattern of `sensors.SENSORS[name]` with this model's noise and dropout."""
    return cls(**{**sensors.get(name).lidar_settings(), **overrides})

  @property
  def num_beams(self) -> int:
    return self.upper_beams + self.lower_beams

  def elevations(self) -> np.ndarray:
    """Nominal beam elevations [B] radians, top beam first."""
    return np.radians(np.concatenate([
        np.linspace(*self.upper_elevation, self.upper_beams),
        np.linspace(*self.lower_elevation, self.lower_beams)]))

  def calibration(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """One sensor's fixed per-beam errors: range bias [B] metres, elevation [B] radians."""
    return (self.beam_range_bias * rng.standard_normal(self.num_beams),
            np.radians(self.beam_elevation_error) * rng.standard_normal(self.num_beams))

  def directions(self, azimuth_offset: float, elevation_error=0.0) -> np.ndarray:
    """Unit ray directions [B * A, 3] in the sensor frame for one revolution, beam-major."""
    az = np.arange(0.0, 360.0, self.azimuth_step) + azimuth_offset
    if self.horizontal_fov < 360:
      az = az[np.abs((az + 180.0) % 360.0 - 180.0) <= self.horizontal_fov / 2]
    az = np.radians(az)
    el = self.elevations() + elevation_error
    ce = np.cos(el)[:, None]
    return np.stack([ce * np.cos(az), ce * np.sin(az),
                     np.broadcast_to(np.sin(el)[:, None], (len(el), len(az)))],
                    -1).reshape(-1, 3)


class Raycaster:
  """An Open3D `RaycastingScene` over a `Scene`, remembering each mesh's label."""

  def __init__(self, scene: Scene):
    import open3d as o3d  # pylint: disable=g-import-not-at-top
    self._o3d = o3d
    self._rc = o3d.t.geometry.RaycastingScene()
    ids = {}
    for label, verts in scene.vertices.items():
      gid = self._rc.add_triangles(o3d.core.Tensor(verts),
                                   o3d.core.Tensor(scene.triangles[label]))
      ids[gid] = label
    self._label_of = np.full(max(ids) + 2, -1, np.int64)
    for gid, label in ids.items():
      self._label_of[gid] = int(label)

  def cast(self, origins: np.ndarray, directions: np.ndarray):
    """Rays [R, 3] + [R, 3] (unit) -> hit distance [R] (inf on miss), label [R]
    (-1 on miss), unit surface normal [R, 3]."""
    rays = np.concatenate([origins, directions], 1).astype(np.float32)
    hit = self._rc.cast_rays(self._o3d.core.Tensor(rays), nthreads=0)
    t = hit['t_hit'].numpy().astype(np.float64)
    gid = hit['geometry_ids'].numpy().astype(np.int64)
    miss = ~np.isfinite(t)
    label = np.where(miss, -1, self._label_of[np.where(miss, len(self._label_of) - 1, gid)])
    return t, label, hit['primitive_normals'].numpy().astype(np.float64)


def scan(raycaster: Raycaster, pose: np.ndarray, model: LidarModel,
         rng: np.random.Generator, calibration=None) -> tuple[np.ndarray, np.ndarray]:
  """One revolution from sensor pose T_world_sensor [4, 4].

  calibration: the sensor's (range bias [B] metres, elevation error [B] radians)
  from `model.calibration`, or None for a perfect sensor.
  Returns points [M, 3] float32 in the sensor frame (metres) and their labels [M].
  """
  azimuth_offset = rng.uniform(0.0, model.azimuth_step)
  bias, el_err = calibration if calibration is not None else (np.zeros(model.num_beams), 0.0)
  true_dirs = model.directions(azimuth_offset, el_err)
  # The sensor reports each return along its nominal beam direction with its own
  # range bias; the mismatch with the true ray is the calibration error of real scans.
  reported = model.directions(azimuth_offset) if calibration is not None else true_dirs
  beam_bias = np.repeat(bias, len(true_dirs) // model.num_beams)
  rot, origin = pose[:3, :3], pose[:3, 3]
  dirs_w = true_dirs @ rot.T
  t, label, normal = raycaster.cast(np.broadcast_to(origin, dirs_w.shape), dirs_w)
  keep = (label >= 0) & (t >= model.min_range) & (t <= model.max_range)
  t, label, normal, dirs_w = t[keep], label[keep], normal[keep], dirs_w[keep]
  reported, beam_bias = reported[keep], beam_bias[keep]
  cos_inc = np.abs(np.einsum('ij,ij->i', normal, dirs_w))
  # Weak returns: grazing incidence and long range fail more often.
  p_drop = (model.dropout + 0.5 * (1 - cos_inc) ** 4 + 0.25 * (t / model.max_range) ** 2)
  p_drop = np.where(label == Label.GLASS, model.glass_dropout, p_drop)
  p_drop = np.where(label == Label.FOLIAGE, np.maximum(p_drop, model.foliage_dropout), p_drop)
  u = rng.uniform(size=len(t))
  noise = model.range_noise * rng.standard_normal(len(t))
  scatter = np.where(label == Label.FOLIAGE,
                     np.abs(rng.standard_normal(len(t))) * model.foliage_scatter, 0.0)
  keep = u >= p_drop
  r = (t + beam_bias + noise + scatter)[keep]
  return (reported[keep] * r[:, None]).astype(np.float32), label[keep].astype(np.int8)
