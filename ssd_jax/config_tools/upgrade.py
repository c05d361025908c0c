"""Stored configs brought to today's keys: the one place that knows past defaults.

A training run, an export and a synthetic dataset store the config they were made with.
Keys added to the configs since then are missing from them; each such key takes the
value every run or dataset made before it used, so an old run resumes, loads and
describes exactly as it trained, and the rest of the code reads every key directly.
Every loader of a stored config calls `upgrade` (runs and exports) or
`upgrade_synthetic` (dataset manifests).
"""

from __future__ import annotations

import json
from typing import Mapping

import ml_collections

# (section, key) -> the value of runs stored before the key existed.
RUN_KEYS = {
    ('model', 'use_orientation'): True,
    ('model', 'orientation_head'): 'mlp',
    ('model', 'self_rotation'): 'gaussian',
    ('model', 'triplet_hinge'): 'cluster',
    ('model', 'attention_normalization'): 'softmax',
    ('model', 'contrastive_weight'): 0.0,
    ('model', 'contrastive_radius'): 1.0,
    ('model', 'contrastive_temperature'): 0.1,
    ('model', 'contrastive_rows'): 'all',
    ('model', 'partner_centers'): False,
    ('model', 'partner_jitter'): 0.0,
    ('model', 'branch_dropout'): 0.0,
    ('model', 'branch_crop_shift'): 0.0,
    ('model', 'branch_crop_radius'): 20.0,
    ('model', 'branch_sensor_rate'): 0.0,
    ('model', 'branch_beam_spacing'): [0.7, 2.5],
    ('model', 'branch_fov_rate'): 0.0,
    ('model', 'branch_fov'): [90.0, 180.0],
    ('data', 'rescan_rate'): 0.0,
    ('data', 'rescan_beams'): 'select',
    ('data', 'pairs'): '',
    ('data', 'pairs_rate'): 0.5,
    ('data', 'pairs_weight'): 'uniform',
    ('data', 'pairs_links'): 1,
    ('train', 'lr_schedule'): 'constant',
    ('train', 'init_scope'): 'descriptor',
    # Runs from before the inference section described as they trained, on 0.2 m grids.
    ('inference', 'num_samples'): 0,
    ('inference', 'draws'): 1,
    ('inference', 'voxel_size'): 0.2,
    ('inference', 'keypoints'): 'all',
}

# (split, key) -> the value of synthetic datasets written before the key existed.
SYNTHETIC_KEYS = {
    ('test_kitti', 'random_yaw'): False,
    ('test_oxford', 'sensor'): 'spinning',
    ('test_oxford', 'line_spacing'): 0.2,
}


def _with(stored: Mapping, keys: Mapping) -> dict:
  """A plain-data copy of `stored` with each missing (section, key) of `keys` added
  (sections that exist; a run's `inference` section is created)."""
  out = json.loads(json.dumps(stored.to_dict() if hasattr(stored, 'to_dict') else stored))
  for (section, key), value in keys.items():
    if section in out or section == 'inference':
      out.setdefault(section, {}).setdefault(key, value)
  return out


def upgrade(stored: Mapping) -> ml_collections.ConfigDict:
  """A run's or an export's stored config (ConfigDict or dict) with today's keys."""
  return ml_collections.ConfigDict(_with(stored, RUN_KEYS))


def upgrade_synthetic(stored: Mapping) -> dict:
  """A synthetic dataset's stored settings (its manifest's config) with today's keys."""
  return _with(stored, SYNTHETIC_KEYS)
