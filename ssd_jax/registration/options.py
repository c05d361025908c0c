"""How a pair is registered: the option vocabulary, `Options` (the register command's
defaults; `Options.paper()`, the paper's protocol) and the learned descriptor's sampling
where the poses are verified (`verified_model`)."""

from __future__ import annotations

import dataclasses

from ssd_jax.infra import errors
from ssd_jax.registration import features

# Each vocabulary's meaning: `Options`' docstring.
KEYPOINTS = ('auto', 'iss', 'learned', 'random')
DESCRIPTORS = ('fpfh', 'learned')
ESTIMATORS = ('rigid', 'upright')
# Compatible samples crowd into the strongest consensus: on a street that looks alike turned
# by 180 degrees its 10 distinct best poses can all be variants of the turned one, where
# uniform draws keep the right pose among them for the verification to pick
# (docs/registration.md).
SAMPLINGS = ('auto', 'compatible', 'uniform')
LEVELS = ('none', 'ground')
# Keypoints, descriptors and whole-scene searches that fail on different pairs: where one's
# candidates hold no right pose, another's sometimes do; and an ICP that does not let the
# points two far scans do not share drag a right candidate away (docs/notes/real_drives.md).
RETRIES = ('structure', 'learned', 'fpfh', 'bev', 'robust')


# How the learned descriptor samples each ball where the poses are verified (the register
# defaults): one draw of 32 points, as the shipped models trained. With the BEV search and
# the verification picking the pose, it registered every pair the paper protocol's 4 draws
# of 64 did on the README's sets, at an eighth of the network's work (docs/notes/speed.md).
VERIFIED_DRAWS = 1
VERIFIED_SAMPLES = 32


def verified_model(model):
  """`model` (an `inference.Model`, or None) describing with VERIFIED_DRAWS samplings of
  VERIFIED_SAMPLES points (of its own num_samples, where fewer)."""
  if model is None:
    return None
  return dataclasses.replace(model, draws=VERIFIED_DRAWS,
                             num_samples=min(model.num_samples, VERIFIED_SAMPLES))


@dataclasses.dataclass(frozen=True)
class Options:
  """How `register` and `register_many` register a pair. The defaults are the register
  command's (docs/registration.md); `Options.paper()` is the paper's protocol.

  keypoints   KEYPOINTS: 'auto' (1,024 farthest-point keypoints, the first 512 tried
              alone where the poses are verified: `coarse_to_fine`), 'iss' (the paper's;
              a pair RANSAC cannot sample is registered again with farthest-point
              keypoints), 'learned' (a detector model), 'random'.
  descriptor  DESCRIPTORS: 'learned' (needs a model) or 'fpfh'.
  estimator   ESTIMATORS: 'upright' (2-point samples of a turn about z and a shift, for
              scans whose z axis is up) or 'rigid' (3-point samples, any rotation).
  sampling    SAMPLINGS, the upright estimator's matches and samples: 'compatible'
              (matches both ways, samples among the pairs of matches that one turn
              about z and shift can fit), 'uniform' (cloud 1's nearest neighbours,
              uniform draws) or 'auto' (compatible with verify = 0, else uniform).
  verify      RANSAC's this many distinct best poses checked against the clouds by ICP
              (`verification`); 0 keeps RANSAC's best as it is.
  bev         the bird's-eye-view search's this many best poses checked with them, where
              they apply: upright estimator and verify > 0 (`bev_candidates`).
  bev_banded  the banded BEV search's best poses, ranked as the verification picks, join
              the BEV search's (`prepared.PreparedPair.bev_poses`): the 'bev' retry's.
  robust_icp  the verification aligns the candidates by ICP with a robust kernel
              (`icp.geman_mcclure`): the 'robust' retry's.
  icp         point-to-plane ICP from the chosen pose (1 m, then 0.5 m).
  free_space  each cloud's origin is its sensor, where the cloud looks like a scan in its
              sensor's frame (`free_space.sensor_centred`): the verification and the
              verdict judge free space and the sides surfaces are seen from. False for
              scans not in their sensors' frames that still look so (a world frame, or
              the other scan's frame near it): their origins are no viewpoints.
  draws       samplings of each ball the learned descriptor averages: None,
              VERIFIED_DRAWS of VERIFIED_SAMPLES points where verify > 0, else the
              model's own; 0 the model's own (`describing`).
  voxel       metres of the grid each cloud is put on first (`to_grid`); None the
              model's (0.2 m), 0 every point as given.
  fpfh_max_nn FPFH's neighbour cap within its 4 m ball (0: none, the paper's).
  seed        RANSAC's (and random keypoints') seed.
  level       LEVELS: 'ground' (each scan whose ground is tilted by `leveling.MIN_TILT_DEG` or
              more is first turned level about its sensor, `leveling`, and every pose
              comes back in the scans' own frames; a pair with a scan of no ground keeps
              its pose as given where verified clear, else is registered with FPFH and
              RANSAC over any rotation, and notes say which) or
              'none' (the clouds as given: z is taken to be up). `register_many` levels
              each cloud once.
  retry       RETRIES in turn (a tuple, or names joined by commas; () or 'none': no
              retry): with learned descriptors and verify > 0, a pose the verdict
              refuses is registered again with each until one is trusted (`retries`):
              'structure' (keypoints from the points above the ground,
              `cloud_features.keypoint_domain`), 'learned' (the model's own sampling of
              its balls), 'fpfh' (the classical descriptor), 'bev' (the first try's
              descriptors, with the banded BEV search's poses: `bev_banded`; where
              `bev_candidates` apply), 'robust' (the 'bev' try's candidates, aligned by
              the robust ICP: `robust_icp`).
  """
  keypoints: str = 'auto'
  descriptor: str = 'learned'
  estimator: str = 'upright'
  verify: int = 10
  bev: int = 5
  icp: bool = False
  draws: int | None = None
  voxel: float | None = None
  fpfh_max_nn: int = features.FPFH_MAX_NN
  seed: int = 0
  level: str = 'ground'
  sampling: str = 'auto'
  retry: tuple[str, ...] = RETRIES
  bev_banded: bool = False
  free_space: bool = True
  robust_icp: bool = False

  def __post_init__(self):
    if isinstance(self.retry, str):
      names = () if self.retry in ('', 'none') else tuple(self.retry.split(','))
      object.__setattr__(self, 'retry', names)
    for name, allowed in (('keypoints', KEYPOINTS), ('descriptor', DESCRIPTORS),
                          ('estimator', ESTIMATORS), ('level', LEVELS),
                          ('sampling', SAMPLINGS)):
      if getattr(self, name) not in allowed:
        raise errors.UserError(f'{name} must be one of {allowed}, got {getattr(self, name)!r}')
    if not set(self.retry) <= set(RETRIES) or len(set(self.retry)) < len(self.retry):
      raise errors.UserError(f"retry must name each of {RETRIES} at most once (or 'none'), "
                             f'got {",".join(self.retry)!r}')
    for name, meaning in (('verify', '0: no verification'), ('bev', '0: no BEV search'),
                          ('fpfh_max_nn', '0: no cap'), ('draws', "0: the model's own"),
                          ('voxel', '0: every point as given')):
      value = getattr(self, name)
      if value is not None and value < 0:
        raise errors.UserError(f'{name} must be >= 0 ({meaning}), got {value}')

  @classmethod
  def paper(cls, descriptor: str = 'fpfh', **overrides) -> 'Options':
    """The paper's protocol: ISS keypoints, RANSAC over any rotation, no verification,
    the clouds as given."""
    return cls(**{'keypoints': 'iss', 'descriptor': descriptor, 'estimator': 'rigid',
                  'verify': 0, 'bev': 0, 'level': 'none', 'sampling': 'uniform',
                  'retry': (), **overrides})

  @property
  def bev_candidates(self) -> int:
    """The BEV search's poses checked: `bev` with the upright estimator and verify > 0
    (its poses turn about z only and are checked with RANSAC's), else 0."""
    return self.bev if self.estimator == 'upright' and self.verify > 0 else 0

  @property
  def retries(self) -> tuple[str, ...]:
    """The tries of `retry` that apply: none unless the descriptor is learned and the
    poses verified (`pipeline.Registrar` skips each learned try the first one already
    is: 'structure' where the keypoints are not 'auto' or the model's own lie there,
    'learned' where the first try samples as the model was trained)."""
    return self.retry if self.descriptor == 'learned' and self.verify > 0 else ()

  @property
  def needs_model(self) -> bool:
    return self.descriptor == 'learned' or self.keypoints == 'learned'

  def describing(self, model):
    """`model` (an `inference.Model`) as these options describe with it (`draws`); None
    where no model is needed; a UserError where one is needed and not given."""
    if not self.needs_model:
      return None
    if model is None:
      raise errors.UserError(f'{self.keypoints} keypoints + {self.descriptor} descriptors '
                             "need a model (e.g. pretrained.load('ours'))")
    if self.draws is None:
      return verified_model(model) if self.verify > 0 else model
    return dataclasses.replace(model, draws=self.draws) if self.draws else model
