"""Levelling: a scan turned so that its ground is horizontal, before anything that assumes
z is up (the learned descriptor's orientation about z, upright RANSAC, the BEV search).

A sensor that is not level (a robot on a slope, a unit mounted pitched down, a backpack or
hand-held scanner) sees its ground tilted. The ground is the largest plane below the sensor
whose normal is within MAX_TILT_DEG of the scan's z: `ground` finds it by RANSAC over
3-point samples of points whose own normals are that steep, and `level` gives the rotation
that turns its normal onto z (the smallest one: no turn about z is added). A scan that
shows no ground but walls of two headings (a hand-held unit pitched up at a building) is
levelled by them (`walls`). A registration of levelled clouds is composed back into the
clouds' own frames (`Leveling.matrix`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ssd_jax.data import preprocess
from ssd_jax.registration import icp

# Degrees: a plane whose normal is farther than this from the scan's z is not its ground
# (walls are ~90 degrees off; a unit pitched down by 30 degrees sees its ground 30 off).
MAX_TILT_DEG = 45.0
# Metres: the ground lies at least this far below the sensor along its normal (a ceiling
# or a roof lies above it).
MIN_SENSOR_HEIGHT = 0.5
# Degrees: a cloud with no ground below its origin is searched again as a cloud in a world
# frame (a map tile), whose ground lies within this of z.
OFF_SENSOR_MAX_TILT_DEG = 15.0
# Metres: a point this close to the plane, whose own normal is within NORMAL_AGREEMENT_DEG
# of the plane's, is on it. Without the normal rule a level band through the walls, poles
# and cars of a scan without ground holds its 0.3 m / height share of them (12 % of a hall
# of 4.5 m walls), and a plane slanted through distant walls passes for a tilted ground
# (a KITTI scan with its ground cut away found one 4-11 degrees off).
PLANE_DISTANCE = 0.15
NORMAL_AGREEMENT_DEG = 30.0
# The ground holds at least this share of the scan's points and MIN_GROUND_POINTS (a car's
# spinning unit sees 35-40 % of its points there; a level band through the bushes and car
# hoods of a KITTI scan with its ground cut away holds 4-5 %; a hand-held solid-state
# unit's ground 250-300 points of 2,500 on the 0.2 m grid).
MIN_GROUND_SHARE = 0.1
MIN_GROUND_POINTS = 200
# A plane tilted PITCHED_DEG or more may hold less: PITCHED_GROUND_SHARE and
# PITCHED_GROUND_POINTS, where at most MAX_BELOW_SHARE of the scan lies more than
# BELOW_DISTANCE metres beneath it. A hand-held solid-state unit (~70 degrees of view)
# pitched up by 15-25 degrees sees its ground only in the lowest part of its view: 3-5 %
# of its points on the 0.2 m grid (100-200 of 2,500-5,000, 1.2-1.8 m below it), nothing
# beneath. A small slanted plane that is no ground has the scene on both sides of it (a
# plane through the distant walls of a KITTI scan with its ground cut away: 41 % beneath;
# a real road's ground 0-10 %, where the road goes downhill beyond it).
PITCHED_DEG = 10.0
PITCHED_GROUND_SHARE = 0.03
PITCHED_GROUND_POINTS = 100
MAX_BELOW_SHARE = 0.1
BELOW_DISTANCE = 0.5
# A scan with fewer points is used as it is: a sparse unit far away returns a few hundred
# ground points at most, too few to tell a missing ground from one it barely saw (real
# cross-sensor re-scans of 576-1,042 points found none, or a wrong plane; tilted re-scans
# of 2,000-3,000 points show theirs).
MIN_POINTS_TO_LEVEL = 1500
# Points the plane is sought and counted among (an even stride; a 0.2 m-grid scan holds
# 3,000-20,000: more cost normals, not accuracy), and RANSAC's samples; a count among them
# stands for stride times as many points of the scan.
SEARCH_POINTS = 2_000
TRIALS = 300
# A scan with no ground (a hand-held unit pitched up at a building, its view all walls) is
# levelled by its walls (`walls`): the up direction, within PITCHED_DEG to
# MAX_WALL_TILT_DEG of the scan's z, about which MIN_WALL_SHARE of its normals lie within
# WALL_DEG of horizontal. On the development drives such scans (HKU_MB, pitched 15-33
# degrees) find their walls' up within 0.3-2.1 degrees of the drive's, with 40-69 % of
# their normals on walls; a scan of trees or slopes scatters its normals (one of them:
# 19 %).
WALL_DEG = 8.0
MIN_WALL_SHARE = 0.35
MAX_WALL_TILT_DEG = 35.0
# The walls face two headings at least: the second eigenvalue of their normals' scatter
# is MIN_WALL_SPREAD of the first or more (HKU_MB's: 0.13-0.41). The normals of one wall,
# or of a corridor's two, are horizontal about any up turned about them.
MIN_WALL_SPREAD = 0.1
# At most MAX_ALONG_UP of the normals lie within WALL_DEG of the up found (a roof, a
# ceiling): a room's floor, ceiling and walls stand at right angles, so its walls are
# level about a horizontal axis as well as about its up. An indoor Livox scan pitched 73
# degrees found an axis 90 degrees off with 12 % of its normals along it; HKU_MB's
# pitched outdoor scans hold 0-8 % along their up.
MAX_ALONG_UP = 0.1
# Up directions tried: an even spiral over the cap within MAX_WALL_TILT_DEG of z, ~1 degree
# apart, the best refined by the walls' normals.
WALL_DIRECTIONS = 4_000


@dataclasses.dataclass(frozen=True)
class Leveling:
  """The turn that levels one cloud: rotation [3, 3] about `center` [3] (metres), the
  ground's normal [3] before it, the tilt in degrees; `note` is '' or the one line saying
  that no ground was found (the cloud is left as it is)."""
  rotation: np.ndarray
  center: np.ndarray
  normal: np.ndarray
  tilt_deg: float
  note: str = ''
  sparse: bool = False   # too few points to look for its ground: used as it is
  by_walls: bool = False   # no ground found: `normal` is the walls' up (`walls`)

  @property
  def turned(self) -> bool:
    return not np.array_equal(self.rotation, np.eye(3))

  def apply(self, points: np.ndarray) -> np.ndarray:
    """points [N, 3] -> the levelled points (float64; as given where nothing is turned)."""
    if not self.turned:
      return points
    points = np.asarray(points, np.float64)
    return (points - self.center) @ self.rotation.T + self.center

  def undo(self, points: np.ndarray) -> np.ndarray:
    """Levelled points [N, 3] -> in the cloud's own frame (float64)."""
    if not self.turned:
      return points
    points = np.asarray(points, np.float64)
    return (points - self.center) @ self.rotation + self.center

  @property
  def matrix(self) -> np.ndarray:
    """[4, 4]: x -> R (x - c) + c. A registration T' of levelled clouds is
    L1^-1 T' L2 in the clouds' own frames."""
    m = np.eye(4)
    m[:3, :3] = self.rotation
    m[:3, 3] = self.center - self.rotation @ self.center
    return m


def unchanged(center: np.ndarray | None = None, note: str = '') -> Leveling:
  return Leveling(np.eye(3), np.zeros(3) if center is None else np.asarray(center, np.float64),
                  np.array([0.0, 0.0, 1.0]), 0.0, note)


def rotation_onto_z(normal: np.ndarray) -> np.ndarray:
  """The smallest rotation [3, 3] that turns the unit vector `normal` onto +z (Rodrigues)."""
  n = np.asarray(normal, np.float64) / np.linalg.norm(normal)
  z = np.array([0.0, 0.0, 1.0])
  axis = np.cross(n, z)
  s, c = np.linalg.norm(axis), float(n @ z)
  if s < 1e-12:
    return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
  k = axis / s
  kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
  return np.eye(3) + s * kx + (1.0 - c) * kx @ kx


def ground(points: np.ndarray, sensor_at_origin: bool = True, seed: int = 0,
           max_tilt_deg: float = MAX_TILT_DEG) -> tuple[np.ndarray, float, int] | None:
  """The ground plane of a scan: points [N, 3] metres -> (unit normal [3] pointing up, the
  height of the sensor (else of the points' centroid) above the plane in metres, the
  scan's points on it, estimated from those searched), or None where no plane within
  `max_tilt_deg` of z holds MIN_GROUND_SHARE of the points, or, tilted by PITCHED_DEG or
  more, PITCHED_GROUND_SHARE with at most MAX_BELOW_SHARE beneath it (a scan of walls
  alone, a tunnel). With `sensor_at_origin` (a scan in its sensor's frame) the plane
  must also lie MIN_SENSOR_HEIGHT below the sensor, which rules out a ceiling or a roof."""
  points = np.asarray(points, np.float64)
  stride = preprocess.even_stride(len(points), SEARCH_POINTS)
  pts = points[::stride]
  centre = np.zeros(3) if sensor_at_origin else pts.mean(axis=0)
  pts = pts - centre
  floor = MIN_SENSOR_HEIGHT if sensor_at_origin else -np.inf
  if len(pts) < MIN_GROUND_POINTS:
    return None
  normals = icp.normals(pts)
  cos_max = np.cos(np.deg2rad(max_tilt_deg))
  steep = np.flatnonzero(np.abs(normals[:, 2]) >= cos_max)
  if len(steep) < 3:
    return None
  rng = np.random.default_rng(seed)
  samples = steep[rng.integers(0, len(steep), (TRIALS, 3))]
  a, b, c = pts[samples[:, 0]], pts[samples[:, 1]], pts[samples[:, 2]]
  n = np.cross(b - a, c - a)
  length = np.linalg.norm(n, axis=1)
  ok = length > 1e-6
  n = n[ok] / length[ok, None]
  n *= np.where(n[:, 2] < 0, -1.0, 1.0)[:, None]              # pointing up
  height = -np.sum(n * a[ok], axis=1)                         # sensor above the plane
  keep = (n[:, 2] >= cos_max) & (height >= floor)
  if not keep.any():
    return None
  n, height = n[keep], height[keep]
  # Only points whose own normal is steep can be on a ground (float32: a 0.15 m band on
  # centred points needs no more, and it halves the count's cost).
  on_pts, on_normals = pts[steep].astype(np.float32), normals[steep].astype(np.float32)
  agree = np.cos(np.deg2rad(NORMAL_AGREEMENT_DEG))

  def on(normal, height):   # normal [3, P], height [P] -> [S, P] bool
    return ((np.abs(on_pts @ normal + height) < PLANE_DISTANCE)
            & (np.abs(on_normals @ normal) >= agree))

  best = int(np.argmax(on(n.T.astype(np.float32), height.astype(np.float32)).sum(0)))
  inliers = on(n[best, :, None].astype(np.float32), np.float32(height[best]))[:, 0]
  if inliers.sum() < 3:
    return None
  # Least squares over the inliers: the plane through their centroid, normal the least
  # principal axis.
  plane = pts[steep][inliers]
  centroid = plane.mean(axis=0)
  normal = icp.least_axis(np.cov((plane - centroid).T)[None])[0]
  normal *= 1.0 if normal[2] >= 0 else -1.0
  height = float(-normal @ centroid)
  # Each searched point stands for `len(points) / len(pts)` of the scan's.
  refit = on(normal[:, None].astype(np.float32), np.float32(height))[:, 0]
  count = int(round(refit.sum() * len(points) / len(pts)))
  if height < floor or normal[2] < cos_max:
    return None
  enough = count >= max(MIN_GROUND_POINTS, MIN_GROUND_SHARE * len(points))
  pitched = (normal[2] <= np.cos(np.deg2rad(PITCHED_DEG))
             and count >= max(PITCHED_GROUND_POINTS, PITCHED_GROUND_SHARE * len(points))
             and np.mean(pts @ normal + height < -BELOW_DISTANCE) <= MAX_BELOW_SHARE)
  if not (enough or pitched):
    return None
  return normal, height, count


def _cap(count: int, max_tilt_deg: float) -> np.ndarray:
  """[count, 3] unit vectors spread evenly over the cap within max_tilt_deg of +z."""
  i = np.arange(count) + 0.5
  z = 1.0 - i / count * (1.0 - np.cos(np.deg2rad(max_tilt_deg)))
  r = np.sqrt(1.0 - z ** 2)
  phi = i * np.pi * (3.0 - np.sqrt(5.0))
  return np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)


def walls(points: np.ndarray, max_tilt_deg: float = MAX_WALL_TILT_DEG) -> np.ndarray | None:
  """The up direction of a scan by its walls: points [N, 3] metres -> unit [3] within
  PITCHED_DEG to max_tilt_deg of z about which MIN_WALL_SHARE of the normals (at
  SEARCH_POINTS of them) lie within WALL_DEG of horizontal, facing two headings at least
  (MIN_WALL_SPREAD), with at most MAX_ALONG_UP along it, or None."""
  points = np.asarray(points, np.float64)
  at = np.arange(0, len(points), preprocess.even_stride(len(points), SEARCH_POINTS))
  normals = icp.normals(points, at=at)
  flat = np.sin(np.deg2rad(WALL_DEG))
  up = _cap(WALL_DIRECTIONS, max_tilt_deg)
  up = up[int(np.argmax((np.abs(normals @ up.T) < flat).sum(0)))]
  for _ in range(3):   # the least axis of the walls' normals: the up they are level about
    on = normals[np.abs(normals @ up) < flat]
    if len(on) < 3:
      return None
    up = icp.least_axis((on.T @ on)[None])[0]
    up *= 1.0 if up[2] >= 0 else -1.0
  cos = np.abs(normals @ up)
  on = normals[cos < flat]
  spread = np.linalg.eigvalsh(on.T @ on)
  tilt = np.degrees(np.arccos(np.clip(up[2], -1.0, 1.0)))
  if (len(on) < MIN_WALL_SHARE * len(normals) or spread[1] < MIN_WALL_SPREAD * spread[2]
      or np.mean(cos > np.cos(np.deg2rad(WALL_DEG))) > MAX_ALONG_UP
      or not PITCHED_DEG <= tilt <= max_tilt_deg):
    return None
  return up


def level(points: np.ndarray, center: np.ndarray | None = None, seed: int = 0,
          min_tilt_deg: float = 0.0, sensor_at_origin: bool = True) -> Leveling:
  """The `Leveling` of a scan (points [N, 3] metres; `sensor_at_origin` as for `ground`, a
  cloud without a ground below its origin searched again without that rule):
  the turn about `center` (default the origin) that makes its ground horizontal; no turn
  where the ground is tilted by less than `min_tilt_deg`. A scan in its sensor's frame with
  no ground is levelled by its walls where they tell its up (`walls`, `by_walls`), else
  left as it is (then `note` says so). A scan of fewer than MIN_POINTS_TO_LEVEL points is
  used as it is (`sparse` set, no note)."""
  if len(points) < MIN_POINTS_TO_LEVEL:
    return dataclasses.replace(unchanged(center), sparse=True)
  found = ground(points, sensor_at_origin, seed)
  if found is None and sensor_at_origin:
    # Perhaps no scan around its sensor (a map tile, a submap centred on its points): its
    # ground need not lie below the origin, but such a cloud is in a near-level world
    # frame, so its ground must be within OFF_SENSOR_MAX_TILT_DEG of z (a pitched scan of
    # walls has steep planes to mistake for one).
    found = ground(points, False, seed, OFF_SENSOR_MAX_TILT_DEG)
  by_walls = False
  if found is None and sensor_at_origin:
    up = walls(points)
    if up is not None:
      found, by_walls = (up,), True
  if found is None:
    return unchanged(center, 'no ground plane found to level it by (a plane below the '
                     f'sensor within {MAX_TILT_DEG:g} degrees of its z axis, holding '
                     f'{MIN_GROUND_SHARE:.0%} of its points, {PITCHED_GROUND_SHARE:.0%} '
                     f'where tilted {PITCHED_DEG:g} degrees or more)')
  normal = found[0]
  tilt = float(np.degrees(np.arccos(np.clip(normal[2], -1.0, 1.0))))
  if tilt < min_tilt_deg:
    return dataclasses.replace(unchanged(center), normal=normal, tilt_deg=tilt)
  return Leveling(rotation_onto_z(normal), np.zeros(3) if center is None else
                  np.asarray(center, np.float64), normal, tilt, by_walls=by_walls)


def from_gravity(gravity, center: np.ndarray | None = None) -> Leveling:
  """The `Leveling` from a measured gravity direction [3] in the scan's frame (an IMU's:
  pointing down): the turn that makes -gravity the z axis."""
  g = np.asarray(gravity, np.float64)
  if g.shape != (3,) or not np.all(np.isfinite(g)) or np.linalg.norm(g) < 1e-9:
    raise ValueError(f'gravity must be three finite numbers, not all 0, got {gravity!r}')
  up = -g / np.linalg.norm(g)
  tilt = float(np.degrees(np.arccos(np.clip(up[2], -1.0, 1.0))))
  return Leveling(rotation_onto_z(up), np.zeros(3) if center is None else
                  np.asarray(center, np.float64), up, tilt)


# Degrees: a scan whose ground is tilted by less than this is used as it is by the
# registration (upright RANSAC's refit in 6 degrees of freedom and the ICP absorb it): the
# real KITTI scans beside the project sit 2.3 degrees off their ground.
MIN_TILT_DEG = 3.0


def level_for(points: np.ndarray, mode: str, name: str, sensor_at_origin: bool = True
              ) -> tuple[Leveling, str]:
  """The `Leveling` of a cloud [N, 3] (about its coordinates' origin, the sensor's where
  `sensor_at_origin`) where `mode` ('none' or 'ground', `options.LEVELS`) asks for it,
  and a one-line note of what was done ('' where nothing is worth saying)."""
  if mode == 'none':
    return unchanged(), ''
  lv = level(points, min_tilt_deg=MIN_TILT_DEG, sensor_at_origin=sensor_at_origin)
  if lv.sparse:
    return lv, (f'{name}: too few points to find its ground (< {MIN_POINTS_TO_LEVEL:,}); '
                'used as it is')
  if lv.note:
    return lv, f'{name}: {lv.note}'
  if lv.by_walls:
    return lv, (f'{name}: no ground found; levelled by its walls, tilted {lv.tilt_deg:.1f} '
                'degrees')
  if lv.turned:
    return lv, f'{name}: levelled, its ground {lv.tilt_deg:.1f} degrees off horizontal'
  return lv, ''


def unlevel(reg, found):
  """A registration (`pair_stages.Registration`) of clouds levelled by `found` (one
  `Leveling` each) in the clouds' own frames: every pose T' -> L1^-1 T' L2."""
  back = lambda t: np.linalg.inv(found[0].matrix) @ t @ found[1].matrix
  many = lambda ts: None if ts is None else np.stack([back(t) for t in ts])
  return dataclasses.replace(reg, transform=back(reg.transform),
                             candidates=many(reg.candidates),
                             verified_poses=many(reg.verified_poses))
