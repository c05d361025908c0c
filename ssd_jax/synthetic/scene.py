"""Procedural street scenes as triangle meshes, seeded.

A scene is a street along a gently curving centreline. Everything is placed in
road coordinates (s, d): s metres along the centreline, d metres to its left.
It holds ground with slopes, curbs and sidewalks, building façades with
storefront recesses, pilasters, windows, doors and cornices, walls and fences in
the gaps, street lights and signs, trees, parked cars and sidewalk clutter. Each
part carries a semantic label, and the LiDAR model uses the label for material
effects (glass drops most returns, foliage scatters).

Street width, building heights, gaps, curvature and object density are drawn
per scene, so no two seeds share a layout.
"""

from __future__ import annotations

import dataclasses
import enum

import numpy as np


class Label(enum.IntEnum):
  GROUND = 0
  BUILDING = 1
  GLASS = 2
  WALL = 3
  POLE = 4
  FOLIAGE = 5
  TRUNK = 6
  CAR = 7
  CLUTTER = 8


@dataclasses.dataclass(frozen=True)
class SceneStyle:
  """Per-scene layout parameters (metres unless noted), drawn by `sample_style`."""
  length: float
  road_half_width: float      # centreline to curb
  sidewalk_width: float
  curb_height: float
  slope: float                # grade along the street (rise per metre)
  bank: float                 # cross slope (rise per metre of d)
  bump_amplitude: float
  bump_wavelength: float
  heading_amplitude: float    # radians; 0 = straight street
  heading_wavelength: float
  building_height: tuple[float, float]
  building_width: tuple[float, float]
  setback: tuple[float, float]
  gap_probability: float
  tree_spacing: tuple[float, float]
  pole_spacing: tuple[float, float]
  parked_car_probability: float
  clutter_per_100m: float


def sample_style(rng: np.random.Generator, length: float) -> SceneStyle:
  """Urban (tall, continuous façades) to suburban (low, gappy, green) streets."""
  urban = rng.uniform()
  low, high = 4.0 + 8.0 * urban, 9.0 + 18.0 * urban
  wavelength = rng.uniform(150.0, 400.0)
  # Keep the curvature radius above 150 m so the road-coordinate mapping stays
  # one-to-one out to the building depth.
  max_amp = wavelength / (2 * np.pi * 150.0)
  return SceneStyle(
      length=length,
      road_half_width=rng.uniform(4.5, 8.0),
      sidewalk_width=rng.uniform(1.8, 4.0),
      curb_height=rng.uniform(0.1, 0.2),
      slope=rng.uniform(-0.04, 0.04),
      bank=rng.uniform(-0.01, 0.01),
      bump_amplitude=rng.uniform(0.0, 0.4),
      bump_wavelength=rng.uniform(40.0, 120.0),
      heading_amplitude=0.0 if rng.uniform() < 0.3 else rng.uniform(0.2, 0.8) * max_amp,
      heading_wavelength=wavelength,
      building_height=(low, high),
      building_width=(8.0, 14.0 + 14.0 * urban),
      setback=(0.0, 1.0 + 5.0 * (1 - urban)),
      gap_probability=0.1 + 0.4 * (1 - urban),
      tree_spacing=(7.0 + 10.0 * urban, 14.0 + 30.0 * urban),
      pole_spacing=(15.0, 35.0),
      parked_car_probability=rng.uniform(0.2, 0.8),
      clutter_per_100m=rng.uniform(2.0, 12.0),
  )


@dataclasses.dataclass(frozen=True)
class Centerline:
  """The street's centreline sampled every `step` metres of arc length."""
  s: np.ndarray        # [M] metres
  xy: np.ndarray       # [M, 2] metres
  heading: np.ndarray  # [M] radians

  @classmethod
  def from_style(cls, style: SceneStyle, rng: np.random.Generator,
                 step: float = 0.5) -> 'Centerline':
    s = np.arange(-20.0, style.length + 20.0 + step, step)
    phase = rng.uniform(0, 2 * np.pi)
    heading = (rng.uniform(-np.pi, np.pi) + style.heading_amplitude *
               np.sin(2 * np.pi * s / style.heading_wavelength + phase))
    d_xy = np.stack([np.cos(heading), np.sin(heading)], -1) * step
    xy = np.concatenate([[[0.0, 0.0]], np.cumsum(d_xy[:-1], 0)], 0)
    return cls(s, xy - xy[np.searchsorted(s, 0.0)], heading)

  def heading_at(self, s: np.ndarray) -> np.ndarray:
    return np.interp(s, self.s, self.heading)

  def to_world(self, s: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Road coordinates (s, d) [...] -> world xy [..., 2]."""
    s, d = np.broadcast_arrays(np.asarray(s, np.float64), np.asarray(d, np.float64))
    x = np.interp(s, self.s, self.xy[:, 0])
    y = np.interp(s, self.s, self.xy[:, 1])
    h = self.heading_at(s)
    return np.stack([x - d * np.sin(h), y + d * np.cos(h)], -1)


@dataclasses.dataclass
class Scene:
  """Triangle soup per label plus the analytic ground, for ray casting and poses."""
  style: SceneStyle
  centerline: Centerline
  bump_phase: float
  vertices: dict[Label, np.ndarray]   # [V, 3] float32 metres
  triangles: dict[Label, np.ndarray]  # [T, 3] uint32

  def ground_height(self, s: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Ground z at road coordinates, curbs included. [...] -> [...] metres."""
    st = self.style
    s, d = np.asarray(s, np.float64), np.asarray(d, np.float64)
    z = st.slope * s + st.bank * d + st.bump_amplitude * np.sin(
        2 * np.pi * s / st.bump_wavelength + self.bump_phase)
    return z + st.curb_height * (np.abs(d) >= st.road_half_width)

  def to_open3d(self) -> dict:
    """Legacy Open3D meshes per label name, e.g. for `o3d.visualization.draw`."""
    import open3d as o3d  # pylint: disable=g-import-not-at-top
    return {label.name.lower(): o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(self.vertices[label].astype(np.float64)),
        o3d.utility.Vector3iVector(self.triangles[label].astype(np.int32)))
            for label in self.vertices}

  @property
  def num_triangles(self) -> int:
    return sum(len(t) for t in self.triangles.values())


class _MeshBuilder:
  """Accumulates primitives per label in road coordinates, placed in the world."""

  _BOX_FACES = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
                         [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]])

  def __init__(self, scene_center: Centerline, ground):
    self.line, self.ground = scene_center, ground
    self.parts: dict[Label, list[tuple[np.ndarray, np.ndarray]]] = {l: [] for l in Label}

  def add(self, label: Label, verts: np.ndarray, tris: np.ndarray) -> None:
    self.parts[label].append((verts, tris))

  def box(self, label: Label, s: float, d: float, z0: float, size, yaw_offset: float = 0.0):
    """Box with its bottom centre at road coords (s, d) and height z0 above the local
    ground; size = (along s, along d, height) metres; aligned with the street."""
    ls, ld, lz = size
    corners = np.array([[-ls, -ld], [ls, -ld], [ls, ld], [-ls, ld]]) / 2
    h = self.line.heading_at(s) + yaw_offset
    rot = np.array([[np.cos(h), -np.sin(h)], [np.sin(h), np.cos(h)]])
    xy = self.line.to_world(s, d) + corners @ rot.T
    base = self.ground(s, d) + z0
    verts = np.concatenate([np.c_[xy, np.full(4, base)], np.c_[xy, np.full(4, base + lz)]])
    self.add(label, verts, self._BOX_FACES)

  def cylinder(self, label: Label, s: float, d: float, z0: float, radius: float,
               height: float, segments: int = 8):
    ang = np.arange(segments) * 2 * np.pi / segments
    xy = self.line.to_world(s, d) + radius * np.c_[np.cos(ang), np.sin(ang)]
    base = self.ground(s, d) + z0
    verts = np.concatenate([np.c_[xy, np.full(segments, base)],
                            np.c_[xy, np.full(segments, base + height)]])
    i = np.arange(segments)
    j = (i + 1) % segments
    side = np.concatenate([np.c_[i, j, j + segments], np.c_[i, j + segments, i + segments]])
    top = np.c_[np.full(segments - 2, segments), i[1:-1] + segments, i[2:] + segments]
    self.add(label, verts, np.concatenate([side, top]))

  def blob(self, label: Label, rng: np.random.Generator, s: float, d: float, z0: float,
           radii, template: tuple[np.ndarray, np.ndarray]):
    """A lumpy ellipsoid (tree crown): unit-sphere template, radially perturbed."""
    unit, tris = template
    lumps = 1.0 + 0.15 * rng.standard_normal(len(unit))
    center = np.r_[self.line.to_world(s, d), self.ground(s, d) + z0]
    self.add(label, center + unit * np.asarray(radii) * lumps[:, None], tris)

  def build(self) -> tuple[dict, dict]:
    vertices, triangles = {}, {}
    for label, parts in self.parts.items():
      if not parts:
        continue
      offsets = np.cumsum([0] + [len(v) for v, _ in parts[:-1]])
      vertices[label] = np.concatenate([v for v, _ in parts]).astype(np.float32)
      triangles[label] = np.concatenate([t + o for (_, t), o in zip(parts, offsets)]
                                        ).astype(np.uint32)
    return vertices, triangles


def _unit_sphere(subdivisions: int = 2) -> tuple[np.ndarray, np.ndarray]:
  """An icosphere: [V, 3] unit vertices and [T, 3] triangles."""
  t = (1 + 5 ** 0.5) / 2
  v = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]],
               np.float64)
  f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9],
                [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2],
                [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
                [8, 6, 7], [9, 8, 1]])
  verts = list(v / np.linalg.norm(v, axis=1, keepdims=True))
  for _ in range(subdivisions):
    cache, faces = {}, []

    def mid(a, b):
      key = (min(a, b), max(a, b))
      if key not in cache:
        m = verts[a] + verts[b]
        verts.append(m / np.linalg.norm(m))
        cache[key] = len(verts) - 1
      return cache[key]

    for a, b, c in f:
      ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
      faces += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
    f = np.array(faces)
  return np.array(verts), f


def _ground_mesh(b: _MeshBuilder, rng: np.random.Generator, style: SceneStyle) -> None:
  """Height field on a road-coordinate grid with vertical curb faces. Off the road it
  is rough (grass, gravel): a few centimetres of random relief per vertex."""
  hw = style.road_half_width
  s = np.arange(-20.0, style.length + 20.0 + 1e-9, 1.0)
  road = np.linspace(-hw + 1e-3, hw - 1e-3, 9)
  outer = hw + np.array([0.0, 0.5, 1.0, 2.0, 3.0, 4.5, 6.5, 9.0, 12.0, 16.0, 22.0, 30.0, 40.0,
                         55.0, 75.0, 95.0, 120.0])
  d = np.unique(np.concatenate([-outer[::-1], road, outer]))
  ss, dd = np.meshgrid(s, d, indexing='ij')
  xy = b.line.to_world(ss, dd)
  roughness = np.where(np.abs(dd) < hw, 0.0,
                       np.where(np.abs(dd) < hw + style.sidewalk_width, 0.02, 0.1))
  z = b.ground(ss, dd) + roughness * rng.standard_normal(ss.shape)
  verts = np.concatenate([xy, z[..., None]], -1).reshape(-1, 3)
  ns, nd = len(s), len(d)
  i, j = np.meshgrid(np.arange(ns - 1), np.arange(nd - 1), indexing='ij')
  v00 = (i * nd + j).ravel()
  v01, v10, v11 = v00 + 1, v00 + nd, v00 + nd + 1
  tris = np.concatenate([np.c_[v00, v10, v11], np.c_[v00, v11, v01]])
  b.add(Label.GROUND, verts, tris)
  # Curb faces: the grid jumps from road to sidewalk height between the last road
  # column and the first sidewalk column; a vertical strip closes the step.
  for sign in (-1.0, 1.0):
    xy_c = b.line.to_world(s, sign * hw)
    lo = b.ground(s, sign * (hw - 1e-3))
    hi = lo + style.curb_height
    verts = np.concatenate([np.c_[xy_c, lo], np.c_[xy_c, hi]])
    k = np.arange(ns - 1)
    b.add(Label.GROUND, verts, np.concatenate([np.c_[k, k + 1, k + 1 + ns],
                                                np.c_[k, k + 1 + ns, k + ns]]))


def _building(b: _MeshBuilder, rng: np.random.Generator, s0: float, width: float,
              side: float, d_front: float, height: float) -> None:
  """A block with a detailed street façade. `side` is +1 (left) or -1 (right)."""
  depth = rng.uniform(8.0, 16.0)
  sc = s0 + width / 2
  storefront = height > 6 and rng.uniform() < 0.4
  floor_h = rng.uniform(2.8, 3.6)
  base = 0.0
  if storefront:
    # Ground floor set back under the upper floors: a recess a descriptor can see.
    recess = rng.uniform(0.8, 2.0)
    b.box(Label.BUILDING, sc, side * (d_front + recess + depth / 2), 0.0,
          (width, depth, floor_h + 0.5))
    base = floor_h + 0.5
  b.box(Label.BUILDING, sc, side * (d_front + depth / 2), base, (width, depth, height - base))
  # Pilasters split the façade into bays.
  bays = max(1, int(width / rng.uniform(3.0, 5.0)))
  bay = width / bays
  if rng.uniform() < 0.6:
    for k in range(bays + 1):
      b.box(Label.BUILDING, s0 + k * bay, side * (d_front - 0.15), base, (0.4, 0.3, height - base))
  # Windows: glass a hair in front of the wall (most returns drop), with a sill.
  win_w, win_h = bay * rng.uniform(0.35, 0.6), floor_h * rng.uniform(0.35, 0.55)
  first = 1 if (storefront or rng.uniform() < 0.5) else 0
  floors = int((height - 0.5) / floor_h)
  for f in range(first, floors):
    z = f * floor_h + 0.9
    if z + win_h > height - 0.4:
      break
    for k in range(bays):
      sk = s0 + (k + 0.5) * bay
      b.box(Label.GLASS, sk, side * (d_front - 0.01), z, (win_w, 0.04, win_h))
      b.box(Label.BUILDING, sk, side * (d_front - 0.08), z - 0.12, (win_w + 0.2, 0.16, 0.12))
  if not storefront:
    door = s0 + (rng.integers(bays) + 0.5) * bay
    b.box(Label.BUILDING, door, side * (d_front - 0.04), 0.0, (1.1, 0.1, 2.2))
  else:
    for k in range(bays):
      b.box(Label.GLASS, s0 + (k + 0.5) * bay, side * (d_front + 0.6), 0.3,
            (bay * 0.8, 0.04, floor_h - 0.6))
  if rng.uniform() < 0.7:
    b.box(Label.BUILDING, sc, side * (d_front - 0.2), height - 0.5, (width + 0.4, 0.4, 0.5))


def _bush(b: _MeshBuilder, rng: np.random.Generator, s: float, d: float, template) -> None:
  r = rng.uniform(0.4, 1.1)
  b.blob(Label.FOLIAGE, rng, s, d, r * 0.6, (r * rng.uniform(1.0, 1.6), r, r * 0.8), template)


def _gap_filler(b: _MeshBuilder, rng: np.random.Generator, s0: float, width: float,
                side: float, d: float, template) -> None:
  """A wall, a fence or a hedge between buildings."""
  u = rng.uniform()
  if u < 0.35:
    b.box(Label.WALL, s0 + width / 2, side * d, 0.0, (width, 0.3, rng.uniform(1.0, 2.5)))
  elif u < 0.7:
    h = rng.uniform(1.0, 2.0)
    n = max(2, int(width / 2.0) + 1)
    for k in range(n):
      b.cylinder(Label.WALL, s0 + k * width / (n - 1), side * d, 0.0, 0.04, h, segments=6)
    for z in (0.3, h - 0.1):
      b.box(Label.WALL, s0 + width / 2, side * d, z, (width, 0.05, 0.08))
  else:
    for sk in np.arange(s0 + 0.6, s0 + width - 0.3, 1.4):
      _bush(b, rng, sk, side * (d + 0.5), template)


def _car(b: _MeshBuilder, rng: np.random.Generator, s: float, d: float) -> None:
  scale = rng.uniform(0.9, 1.15)
  yaw = rng.normal(0.0, 0.03)
  length, width = 4.3 * scale, 1.8 * scale
  b.box(Label.CAR, s, d, 0.3, (length, width, 0.75 * scale), yaw)
  b.box(Label.CAR, s - 0.2 * length * rng.uniform(0, 1), d, 0.3 + 0.75 * scale,
        (0.55 * length, 0.9 * width, 0.55 * scale), yaw)
  for ds in (-0.32, 0.32):
    for dd in (-0.42, 0.42):
      b.box(Label.CAR, s + ds * length, d + dd * width, 0.0, (0.65, 0.25, 0.6), yaw)


def _clutter(b: _MeshBuilder, rng: np.random.Generator, s: float, d: float) -> None:
  kind = rng.integers(4)
  if kind == 0:    # bin
    b.box(Label.CLUTTER, s, d, 0.0, (0.6, 0.6, rng.uniform(0.9, 1.3)), rng.uniform(-0.5, 0.5))
  elif kind == 1:  # bollard
    b.cylinder(Label.CLUTTER, s, d, 0.0, 0.1, 0.9)
  elif kind == 2:  # bench
    b.box(Label.CLUTTER, s, d, 0.0, (1.8, 0.5, 0.45))
    b.box(Label.CLUTTER, s, d + 0.25 * np.sign(d), 0.45, (1.8, 0.08, 0.45))
  else:            # electrical cabinet
    b.box(Label.CLUTTER, s, d, 0.0, (1.0, 0.5, 1.4))


def _varied_clutter(b: _MeshBuilder, rng: np.random.Generator, s: float, d: float,
                    template) -> None:
  """Sidewalk objects of eight kinds, each at a random yaw and size.

  `_clutter`'s objects face the street, so in a cloud turned about z they tell little
  apart; these give a 2-4 m neighbourhood a shape of its own that survives the turn.
  """
  kind, yaw = rng.integers(8), rng.uniform(-np.pi, np.pi)
  if kind == 0:    # box or bin
    b.box(Label.CLUTTER, s, d, 0.0,
          (rng.uniform(0.4, 1.5), rng.uniform(0.4, 1.2), rng.uniform(0.5, 1.6)), yaw)
  elif kind == 1:  # a row of one to three bollards
    for k in range(rng.integers(1, 4)):
      b.cylinder(Label.CLUTTER, s + 1.2 * k, d, 0.0, rng.uniform(0.08, 0.2), rng.uniform(0.6, 1.2))
  elif kind == 2:  # bench with a backrest
    # The backrest is shifted along s only, not across the turned seat, so it sits
    # askew: the documented synthetic_small_varied split is drawn with it.
    b.box(Label.CLUTTER, s, d, 0.0, (1.8, 0.5, 0.45), yaw)
    b.box(Label.CLUTTER, s + 0.25 * np.sin(yaw), d, 0.45, (1.8, 0.08, 0.45), yaw)
  elif kind == 3:  # electrical cabinet
    b.box(Label.CLUTTER, s, d, 0.0, (1.0, 0.5, 1.4), yaw)
  elif kind == 4:  # boulder
    r = rng.uniform(0.3, 1.0)
    b.blob(Label.CLUTTER, rng, s, d, r * 0.4, (r * rng.uniform(0.8, 1.6), r, r * 0.7), template)
  elif kind == 5:  # table on a central leg
    b.box(Label.CLUTTER, s, d, 0.7, (1.2, 0.8, 0.06), yaw)
    b.cylinder(Label.CLUTTER, s, d, 0.0, 0.05, 0.7)
  elif kind == 6:  # L-shaped low wall
    l1, l2 = rng.uniform(1.0, 3.0, 2)
    b.box(Label.CLUTTER, s, d, 0.0, (l1, 0.25, rng.uniform(0.4, 1.2)), yaw)
    b.box(Label.CLUTTER, s + l1 / 2 * np.cos(yaw), d + l1 / 2 * np.sin(yaw), 0.0,
          (0.25, l2, rng.uniform(0.4, 1.2)), yaw)
  else:            # planter with a shrub
    w = rng.uniform(0.6, 1.4)
    b.box(Label.CLUTTER, s, d, 0.0, (w, w, 0.5), yaw)
    _bush(b, rng, s, d, template)


def _angled_car(b: _MeshBuilder, rng: np.random.Generator, s: float, d: float) -> None:
  """A car parked at up to ±34° to the curb, of 0.8-1.3 times the usual size."""
  scale, yaw = rng.uniform(0.8, 1.3), rng.uniform(-0.6, 0.6)
  length, width = 4.3 * scale, 1.8 * scale
  b.box(Label.CAR, s, d, 0.3, (length, width, rng.uniform(0.6, 1.2) * scale), yaw)
  b.box(Label.CAR, s, d, 0.3 + 0.75 * scale, (rng.uniform(0.4, 0.7) * length, 0.9 * width,
                                              0.55 * scale), yaw)


def make_scene(rng: np.random.Generator, length: float = 240.0, clutter_scale: float = 1.0,
               varied_objects: bool = False) -> Scene:
  """A new random street about `length` metres long.

  `clutter_scale` multiplies the drawn density of sidewalk objects. `varied_objects`
  draws them from eight kinds at random yaws (`_varied_clutter`) and parks half of
  the cars at an angle; with neither, the random draws are those of the default scene.
  """
  style = sample_style(rng, length)
  style = dataclasses.replace(style, clutter_per_100m=style.clutter_per_100m * clutter_scale)
  line = Centerline.from_style(style, rng)
  scene = Scene(style, line, rng.uniform(0, 2 * np.pi), {}, {})
  b = _MeshBuilder(line, scene.ground_height)
  hw, sw = style.road_half_width, style.sidewalk_width
  _ground_mesh(b, rng, style)
  crown, bush = _unit_sphere(2), _unit_sphere(1)
  end = length + 15.0
  for side in (-1.0, 1.0):
    s = -15.0 + rng.uniform(0, 5)
    while s < end:       # buildings and what fills the gaps between them
      width = rng.uniform(*style.building_width)
      setback = rng.uniform(*style.setback)
      if rng.uniform() < style.gap_probability:
        gap = rng.uniform(3.0, 12.0)
        _gap_filler(b, rng, s, gap, side, hw + sw + 0.2, bush)
        s += gap
      else:
        _building(b, rng, s, width, side, hw + sw + setback, rng.uniform(*style.building_height))
        if setback > 1.5 and rng.uniform() < 0.6:   # front-yard shrubs
          for sk in s + rng.uniform(0, width, rng.integers(1, 4)):
            _bush(b, rng, sk, side * (hw + sw + setback * rng.uniform(0.3, 0.7)), bush)
        s += width + (rng.uniform(0.0, 0.6) if rng.uniform() < 0.5 else 0.0)
    s = -15.0 + rng.uniform(0, 10)
    while s < end:       # street lights and signs at the curb
      if rng.uniform() < 0.7:
        h = rng.uniform(6.0, 9.0)
        b.cylinder(Label.POLE, s, side * (hw + 0.5), 0.0, rng.uniform(0.08, 0.13), h)
        b.box(Label.POLE, s, side * (hw - 0.3), h - 0.3, (0.15, 1.6, 0.12))
      else:
        h = rng.uniform(2.2, 3.0)
        b.cylinder(Label.POLE, s, side * (hw + 0.4), 0.0, 0.04, h, segments=6)
        b.box(Label.POLE, s, side * (hw + 0.4), h, (0.6, 0.05, rng.uniform(0.4, 0.8)),
              rng.uniform(-0.3, 0.3) + np.pi / 2 * rng.integers(2))
      s += rng.uniform(*style.pole_spacing)
    s = -15.0 + rng.uniform(0, 10)
    while s < end:       # trees on the sidewalk
      trunk_h, r = rng.uniform(1.8, 3.5), rng.uniform(1.3, 3.2)
      d = side * (hw + sw * rng.uniform(0.5, 0.8))
      b.cylinder(Label.TRUNK, s, d, 0.0, rng.uniform(0.12, 0.3), trunk_h + r * 0.5, segments=7)
      b.blob(Label.FOLIAGE, rng, s, d, trunk_h + r * 0.8, (r, r, r * rng.uniform(0.8, 1.3)), crown)
      s += rng.uniform(*style.tree_spacing)
    s = -15.0 + rng.uniform(0, 10)
    while s < end:       # trees behind the buildings, seen through the gaps
      r = rng.uniform(2.0, 4.0)
      d = side * (hw + sw + rng.uniform(22.0, 60.0))
      b.blob(Label.FOLIAGE, rng, s, d, rng.uniform(2.0, 4.0) + r, (r, r, r), bush)
      s += rng.uniform(6.0, 16.0)
    s = -15.0 + rng.uniform(0, 6)
    while s < end:       # parked cars along the curb
      if rng.uniform() < style.parked_car_probability:
        d = side * (hw - 1.1 - rng.uniform(0, 0.2))
        if varied_objects and rng.uniform() < 0.5:
          _angled_car(b, rng, s, d)
        else:
          _car(b, rng, s, d)
      s += rng.uniform(5.5, 7.5)
    for _ in range(rng.poisson(style.clutter_per_100m * (end + 15) / 100)):
      s, d = rng.uniform(-15, end), side * (hw + rng.uniform(0.4, sw - 0.3))
      if varied_objects:
        _varied_clutter(b, rng, s, d, bush)
      else:
        _clutter(b, rng, s, d)
  scene.vertices, scene.triangles = b.build()
  return scene
