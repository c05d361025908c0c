"""One function per evaluation, from config to written outputs, shared by the
single-evaluation entry points and `experiments.reproduce`. Each returns the
Markdown it wrote."""

from __future__ import annotations

import os
from typing import Sequence

import ml_collections

from ssd_jax.data import benchmarks, clusters
from ssd_jax.evaluation import (descriptor_matching, feature_store, precision, registration,
                                repeatability, report)


def load_pairs(config: ml_collections.ConfigDict) -> list:
  """The registration pairs of config.dataset, the first config.max_pairs (0 = all)."""
  pairs = benchmarks.read_registration_set(config.dataset)
  return pairs[:config.max_pairs] if config.max_pairs else pairs


def open_store(config: ml_collections.ConfigDict, rows: Sequence[str]):
  """Load the checkpoints the rows need -> (FeatureStore, {name: why missing})."""
  models, missing = feature_store.load_models(config.checkpoints, feature_store.model_names(rows))
  return feature_store.FeatureStore(models, config.seed, config.fpfh_max_nn), missing


def run_registration(config, pairs, store, missing, workdir: str, paper_set: str,
                     description: str, name: str = 'registration') -> str:
  """Tables I / II on `pairs`: WORKDIR/{name}.md, .csv and {name}_pairs.jsonl."""
  rows = list(config.rows)
  os.makedirs(workdir, exist_ok=True)
  with open(os.path.join(workdir, f'{name}_pairs.jsonl'), 'w') as log:
    results = registration.register_pairs(
        pairs, feature_store.runnable_rows(rows, missing), store, seed=config.seed,
        inlier_threshold=config.inlier_threshold, confidence=config.confidence,
        max_trials=config.max_trials, log=log, desc=name)
  return report.registration_outputs(results, rows, missing, workdir, paper_set, description, name)


def run_precision(config, pairs, store, missing, workdir: str, description: str,
                  name: str = 'precision') -> str:
  """Fig. 4 on `pairs`: WORKDIR/{name}.csv, .md and .png."""
  rows = list(config.rows)
  os.makedirs(workdir, exist_ok=True)
  results = precision.evaluate_precision(pairs, feature_store.runnable_rows(rows, missing), store,
                                         overlap_radius=config.overlap_radius, desc=name)
  return report.precision_outputs(results, rows, missing, workdir, config.read_at, description,
                                  name)


def run_descriptor_matching(config, folder, workdir: str, description: str | None = None) -> str:
  """Table III on the cluster pairs under `folder`: WORKDIR/descriptor_matching.md, .csv,
  _roc.png and distances.npz."""
  pairs = clusters.read_cluster_pairs(folder)
  if config.max_pairs:
    pairs = pairs[:config.max_pairs]
  names = list(config.descriptors)
  models, missing = feature_store.load_models(config.checkpoints,
                                         [n for n in names if n != 'fpfh'])
  descriptors = {n: (None if n == 'fpfh' else models[n]) for n in names if n not in missing}
  distances, iss_distance = descriptor_matching.describe_pairs(
      pairs, descriptors, radius=config.radius, fpfh_max_nn=config.fpfh_max_nn)
  labels = [p.label for p in pairs]
  os.makedirs(workdir, exist_ok=True)
  descriptor_matching.save_distances(os.path.join(workdir, 'distances.npz'), labels, distances,
                                     iss_distance)
  return report.descriptor_matching_outputs(
      distances, labels, iss_distance, tuple(config.r_th), missing, workdir,
      description or f'{folder} ({len(pairs)} pairs)', recall=config.recall)


def run_repeatability(config, pairs, store, missing, workdir: str, description: str,
                      name: str = 'repeatability') -> str:
  """Keypoint repeatability of config.keypoint_sources on `pairs`: WORKDIR/{name}.md, .csv."""
  sources = [s for s in config.keypoint_sources if s not in missing]
  os.makedirs(workdir, exist_ok=True)
  results = repeatability.evaluate_repeatability(pairs, sources, store,
                                                 config.repeatability_radius)
  return report.repeatability_outputs(results, list(config.keypoint_sources), missing, workdir,
                                      description, config.repeatability_radius, name)
