"""ssd_jax.viz: the figures show what they are given (read back as pixels)."""

import matplotlib.image
import numpy as np

from ssd_jax import viz


def _share(path, rgb, tol=0.12):
  """Share of the image's pixels within `tol` of the colour `rgb` (0..1 per channel)."""
  img = matplotlib.image.imread(path)[..., :3]
  return float(np.mean(np.all(np.abs(img - np.asarray(rgb)) < tol, axis=-1)))


def _cloud(seed=0, n=4000):
  rng = np.random.default_rng(seed)
  return rng.uniform(-20, 20, (n, 3)) * np.array([1, 1, 0.1])


def test_keypoints_are_red_dots_one_panel_per_detector(tmp_path):
  points = _cloud()
  viz.plot_keypoints(points, {'iss': points[:200], 'none': points[:0]}, tmp_path / 'k.png')
  img = matplotlib.image.imread(tmp_path / 'k.png')
  left, right = img[:, :img.shape[1] // 2], img[:, img.shape[1] // 2:]
  red = lambda im: np.mean((im[..., 0] > 0.8) & (im[..., 1] < 0.2) & (im[..., 2] < 0.2))
  assert red(left) > 1e-3 and red(right) == 0.0
  assert img.shape[1] > 1.7 * img.shape[0]     # two panels side by side


def test_registration_figure_draws_inlier_matches_only(tmp_path):
  p1 = _cloud(0)
  p2 = p1 + np.array([3.0, 0.0, 0.0])
  kp = p1[::40]
  green = (0.17, 0.63, 0.17)   # matplotlib's tab:green
  viz.plot_registration(p1, p2, kp, kp + [3.0, 0, 0], np.ones(len(kp), bool), tmp_path / 'in.png')
  viz.plot_registration(p1, p2, kp, kp + [3.0, 0, 0], np.zeros(len(kp), bool), tmp_path / 'out.png')
  assert _share(tmp_path / 'in.png', green, tol=0.2) > 1e-4
  assert _share(tmp_path / 'out.png', green, tol=0.2) == 0.0


def test_curves_are_drawn_where_their_values_lie(tmp_path):
  x = np.linspace(0.1, 10, 100)
  viz.plot_precision(x, {'high': np.ones(100)}, tmp_path / 'hi.png')
  viz.plot_precision(x, {'low': np.zeros(100) + 0.05}, tmp_path / 'lo.png')
  blue = (0.12, 0.47, 0.71)    # the first curve's colour (tab:blue)
  rows = lambda p: np.flatnonzero(np.any(np.all(np.abs(
      matplotlib.image.imread(p)[..., :3] - blue) < 0.12, axis=-1), axis=1))
  assert rows(tmp_path / 'hi.png').mean() < rows(tmp_path / 'lo.png').mean()   # 100 % is higher up
