"""The paper's evaluations: FPR@95, precision curve, overlap mask, cluster reader and
`experiments.evaluate` with the reproduce config end to end on a tiny synthetic data root."""

import csv
import dataclasses
import json
import os
import subprocess
import sys

import jax
import numpy as np
import pytest

from ssd_jax import geometry, inference, pretrained, train
from ssd_jax.infra import errors
from ssd_jax.configs.training import paper_small
from ssd_jax.configs.evals import registration as registration_config
from ssd_jax.data import clean, clusters, io, registration_sets
from ssd_jax.registration import cloud_features, features, metrics, pipeline
from ssd_jax.registration import options as options_lib
from ssd_jax.evaluation import (descriptor_matching, evaluators, feature_store, fingerprint,
                                learning_curve, orientation, precision, registration,
                                repeatability)
from tests.conftest import shared_path, tiny_config_dict

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _transform(yaw_deg, t):
  return np.asarray(geometry.make_transform(
      np.asarray(geometry.rotation_z(np.deg2rad(yaw_deg)), np.float64), np.asarray(t, np.float64)))


# ---- descriptor matching (docs/method.md §4) -------------------------------------------------

def test_fpr_at_95_recall_by_hand():
  pos = np.arange(1, 21) * 0.1                       # 0.1 ... 2.0
  neg = np.array([0.5, 1.0, 1.85, 1.95, 3.0])
  d = np.r_[pos, neg]
  labels = np.r_[np.ones(20, int), np.zeros(5, int)]
  perm = np.random.default_rng(0).permutation(len(d))  # order must not matter
  # 95 % of 20 positives = 19 -> threshold = 19th smallest = 1.9; negatives <= 1.9: 3 of 5.
  fpr, thr = descriptor_matching.fpr_at_recall(d[perm], labels[perm])
  assert thr == pytest.approx(1.9) and fpr == pytest.approx(0.6)
  # 50 %: 10th smallest = 1.0; negatives <= 1.0: 0.5 and 1.0.
  assert descriptor_matching.fpr_at_recall(d, labels, 0.5) == pytest.approx((0.4, 1.0))
  assert np.isnan(descriptor_matching.fpr_at_recall(pos, np.ones(20, int))[0])


def test_roc_curve_and_iss_filter_counts():
  d = np.array([0.1, 0.2, 0.3, 0.4])
  labels = np.array([1, 0, 1, 0])
  fpr, tpr = descriptor_matching.roc_curve(d, labels)
  np.testing.assert_allclose(fpr, [0, 0, 0.5, 0.5, 1])
  np.testing.assert_allclose(tpr, [0, 0.5, 0.5, 1, 1])
  iss = np.array([[0.05, 0.15], [0.3, 0.1], [np.inf, 0.0], [0.2, 0.35]])
  res = descriptor_matching.filtered_results({'x': d}, labels, iss, r_th=(0.1, 0.2, 0.4))
  assert [r for r, _, _ in res] == [None, 0.1, 0.2, 0.4]
  # both clusters within r_th: 0.2 keeps pair 0; 0.4 keeps pairs 0, 1 and 3.
  assert [c for _, c, _ in res] == [(2, 2), (0, 0), (1, 0), (1, 2)]
  assert res[0][2]['x'] == pytest.approx(0.5) and np.isnan(res[2][2]['x'])


def test_cluster_reader_formats_and_errors(tmp_path):
  for name in ('3_0.bin', '3_1.bin', '7_0.bin', '7_1.bin', 'a.bin', 'b.bin'):
    io.write_bin(tmp_path / name, np.zeros((4, 3), np.float32), np.zeros((4, 3), np.float32))
  (tmp_path / 'filenames.txt').write_text('pair\tcluster_0\tcluster_1\tlabel\n'
                                          '3\t3_0.bin\t3_1.bin\t1\n7 0\n9, a.bin, b.bin, 1\n')
  pairs = clusters.read_cluster_pairs(tmp_path)
  assert [(p.index, p.cluster0.name, p.cluster1.name, p.label) for p in pairs] == [
      (3, '3_0.bin', '3_1.bin', 1), (7, '7_0.bin', '7_1.bin', 0), (9, 'a.bin', 'b.bin', 1)]
  (tmp_path / 'filenames.txt').write_text('header\n4 1\n')
  with pytest.raises(io.CloudFileError, match=r'filenames.txt:2: cluster file .*4_0.bin is missing'):
    clusters.read_cluster_pairs(tmp_path)
  (tmp_path / 'filenames.txt').write_text('header\n3 maybe\n')
  with pytest.raises(io.CloudFileError, match=r'filenames.txt:2: expected'):
    clusters.read_cluster_pairs(tmp_path)
  with pytest.raises(io.CloudFileError, match='no filenames.txt'):
    clusters.read_cluster_pairs(tmp_path / 'nowhere')


def test_fpfh_at_center_is_finite_and_depends_on_the_centre():
  rng = np.random.default_rng(0)
  plane = np.c_[rng.uniform(-3, 3, (800, 2)), 0.02 * rng.normal(size=800)].astype(np.float32)
  box = np.r_[plane, np.c_[rng.uniform(-3, 3, 300), np.full(300, 1.0), rng.uniform(0, 2, 300)]]
  d = descriptor_matching.fpfh_at_center(box.astype(np.float32))
  assert d.shape == (33,) and np.isfinite(d).all() and d.sum() > 0
  moved = descriptor_matching.fpfh_at_center((box - [0, 0.5, 0]).astype(np.float32))
  assert np.abs(d - moved).sum() > 1.0   # a different centre, a different descriptor


# ---- precision (docs/method.md §4) ----------------------------------------------------------

def test_overlap_mask_counts_keypoints_near_the_moved_cloud():
  cloud2 = np.array([[0.0, 0, 0], [10, 0, 0]])
  t12 = _transform(90, [1, 2, 3])                  # cloud 2's origin lands at (1, 2, 3)
  kp1 = np.array([[1, 2, 3.5], [1, 2.74, 3], [1.76, 2, 3], [1, 12, 3], [1, 12.8, 3], [11, 2, 3]])
  mask = precision.overlap_mask(kp1, cloud2, t12)
  # (10, 0, 0) lands at (1, 12, 3); (11, 2, 3) is where it would be without the rotation.
  np.testing.assert_array_equal(mask, [True, True, False, True, False, False])


def test_precision_of_perfect_and_random_descriptors():
  rng = np.random.default_rng(0)
  kp = rng.uniform(-25, 25, (400, 3)) * [1, 1, 0.1]
  t12 = _transform(30, [4, -2, 0.5])
  kp2 = geometry.apply_transform(geometry.invert_transform(t12), kp)   # cloud 2's own frame
  unique = rng.normal(size=(400, 32))            # the same descriptor for the same point
  perfect = precision.precision_curve(precision.match_errors(kp, unique, kp2, unique, t12))
  assert precision.value_at(perfect, 0.1) == 1.0
  shuffled = unique[rng.permutation(400)]
  rand = precision.precision_curve(precision.match_errors(kp, unique, kp2, shuffled, t12))
  assert precision.value_at(rand, 1.0) < 0.05 and precision.value_at(rand, 10.0) < 0.3
  assert np.all(np.diff(rand) >= 0) and np.isnan(precision.precision_curve([])).all()


# ---- learned descriptors of many clusters at once -----------------------------------------

def test_describe_clusters_equals_describe_per_cluster():
  config = paper_small.get_config()
  config.model.num_samples = 16
  state = train.create_train_state(config, jax.random.key(0))
  model = inference.Model.from_config(config, {'params': state.params,
                                               'batch_stats': state.batch_stats})
  rng = np.random.default_rng(1)
  clouds = [rng.normal(size=(n, 3)).astype(np.float32) for n in (5, 40, 300)]
  clouds.append(rng.uniform(3, 4, (30, 3)).astype(np.float32))   # nothing within 2 m
  batched = inference.describe_clusters(model, clouds, chunk=2)
  one = np.concatenate([inference.describe(model, c, np.zeros((1, 3), np.float32))
                        for c in clouds])
  np.testing.assert_allclose(batched, one, atol=1e-5)
  # Averaged over draws alike (the 4th cloud has no neighbour: zero in every draw).
  model = dataclasses.replace(model, draws=3)
  batched = inference.describe_clusters(model, clouds[:3], chunk=2)
  one = np.concatenate([inference.describe(model, c, np.zeros((1, 3), np.float32))
                        for c in clouds[:3]])
  np.testing.assert_allclose(batched, one, atol=1e-5)
  assert np.abs(batched[2] - inference.describe_clusters(
      dataclasses.replace(model, draws=1), clouds[2:3])[0]).max() > 1e-3
  with pytest.raises(ValueError, match='cloud 1: .* NaN'):
    inference.describe_clusters(model, [clouds[0], np.full((3, 3), np.nan, np.float32)])


def test_success_by_relative_yaw_by_hand():
  """Pairs turned by 10, 50, 100, 170 and -175 degrees fall in the bins 0-45, 45-90,
  90-135, 135-180 (twice); a row's success is counted per bin."""
  pairs = [registration_sets.RegistrationPair('s', 0, i, None, None, np.asarray(
      geometry.make_transform(np.asarray(geometry.rotation_z(np.radians(yaw))), np.zeros(3))))
           for i, yaw in enumerate([10.0, 50.0, 100.0, 170.0, -175.0])]
  ok = lambda *s: [{'success': v} for v in s]
  results = {'iss+fpfh': ok(True, False, True, True, False), 'iss+ours': ok(*[True] * 5)}
  header, table = registration.yaw_table(pairs, results, ['iss+fpfh', 'iss+ours', 'iss+x'])
  assert header[1:] == ['0-45° (1 pairs)', '45-90° (1 pairs)', '90-135° (1 pairs)',
                        '135-180° (2 pairs)']
  assert table == [['ISS kpt + FPFH desc', '100.00', '0.00', '100.00', '50.00'],
                   ['ISS kpt + Ours desc', '100.00', '100.00', '100.00', '100.00']]


# ---- reproduce end to end ------------------------------------------------------------------

@pytest.fixture(scope='module')
def tiny_checkpoint(synthetic_root, tmp_path_factory):
  config = tiny_config_dict()
  config.data.path = str(synthetic_root / 'train')
  workdir = tmp_path_factory.mktemp('ckpt') / 'ours'
  train.train_and_evaluate(config, str(workdir))
  return workdir


def _csv(path):
  with open(path) as f:
    return list(csv.reader(f))


@pytest.mark.multiprocess
@pytest.mark.slow
def test_reproduce_on_a_synthetic_root(synthetic_root, tiny_checkpoint, tmp_path):
  out = tmp_path / 'out'
  run = subprocess.run(
      [sys.executable, '-m', 'experiments.evaluate', '--config=configs/evals/reproduce_small.py',
       f'--config.data_root={synthetic_root}', f'--workdir={out}', '--config.max_pairs=2',
       '--config.fpfh_max_nn=50', f'--config.checkpoints.ours={tiny_checkpoint}',
       f'--config.checkpoints.feat3dnet={tmp_path / "none"}',
       f'--config.checkpoints.ours_detector={tmp_path / "none"}'],
      cwd=ROOT, capture_output=True, text=True, timeout=900)
  assert run.returncode == 0, run.stderr[-3000:]
  report = (out / 'report.md').read_text()
  for heading in ('## Table I', '## Table II', '## Fig. 4: precision on oxford',
                  '## Table III', '## Figures 3, 5 and 6', '## Skipped'):
    assert heading in report, heading
  assert 'Ours: `' in report and '(step 4)' in report
  assert f'3DFeat-Net: `{tmp_path / "none"}` **missing**' in report
  assert 'Ours (re-scan views): `ours_rescan` not loaded: no row uses it' in report
  assert '3DFeat-Net keypoints' in report and 'no such checkpoint directory' in report
  # the paper's four keypoint x descriptor rows say which detector each uses
  assert "- 3DFeat-Net kpt: 3DFeat-Net's attention, trained by its" in report
  assert '- Ours (self-sup. detector) kpt: the self-supervised attention' in report
  # each registration table is followed by its success per bin of relative yaw
  assert report.count("Success (%) by the pair's relative yaw") == 2
  yaw = _csv(out / 'table1_oxford_yaw.csv')
  assert yaw[0][0] == 'keypoints + descriptor' and yaw[1][0] == 'ISS kpt + FPFH desc'
  for png in ('fig4_precision_oxford.png', 'descriptor_matching_roc.png', 'figures_keypoints.png',
              'figures_oxford_iss_ours.png'):
    assert (out / png).stat().st_size > 10_000, png
  assert '[1/8] Table I' in run.stderr and '[8/8] Figures' in run.stderr

  # The table's numbers are recomputed: redo ISS + FPFH on the same two pairs here.
  pairs = registration_sets.read_registration_set(synthetic_root / 'test_oxford')[:2]
  store = feature_store.FeatureStore({}, seed=0, fpfh_max_nn=50)
  res = registration.register_pairs(pairs, ['iss+fpfh'], store, progress=False)['iss+fpfh']
  table = {r[0]: r for r in _csv(out / 'table1_oxford.csv')}
  row = table['ISS kpt + FPFH desc']
  assert row[1] == '2' and float(row[5]) == pytest.approx(100 * np.mean([r['success'] for r in res]))
  assert float(row[6]) == pytest.approx(np.mean([r['trials'] for r in res]), abs=0.5)
  assert table['ISS kpt + Ours desc'][1] == '2'
  assert table['3DFeat-Net kpt + Ours desc'][1] == 'missing'
  curve = precision.evaluate_precision(pairs, ['iss+fpfh'], store, progress=False)['iss+fpfh']
  prec = _csv(out / 'fig4_precision_oxford.csv')
  assert prec[0][:2] == ['x (m)', 'iss+fpfh'] and len(prec) == 101
  np.testing.assert_allclose([float(r[1]) for r in prec[1:]], curve['curve'], atol=1e-5)

  # Repeatability: ISS and random ran, the missing detectors are reported as missing.
  rep = {r[0]: r for r in _csv(out / 'repeatability_oxford.csv')}
  iss = repeatability.evaluate_repeatability(pairs, ['iss'], store, progress=False)['iss']
  assert float(rep['ISS'][1]) == pytest.approx(100 * iss['repeatability'], abs=0.01)
  assert rep['3DFeat-Net'][1] == 'missing' and '## Keypoint repeatability on kitti' in report

  # Table III from the per-pair distances it saved, and the cluster labels on disk.
  saved = np.load(out / 'descriptor_matching_distances.npz')
  labels = [p.label for p in clusters.read_cluster_pairs(synthetic_root / 'clusters')]
  np.testing.assert_array_equal(saved['labels'], labels)
  dm = {r[0]: r for r in _csv(out / 'descriptor_matching.csv')}
  for name, key in (('FPFH', 'distance_fpfh'), ('Ours', 'distance_ours')):
    fpr = descriptor_matching.fpr_at_recall(saved[key], labels)[0]
    assert float(dm[name][1]) == pytest.approx(100 * fpr, abs=0.01)
  assert dm['pairs (pos, neg)'][1] == '24 (12, 12)'
  assert dm['3DFeat-Net'][1] == 'missing'


@pytest.mark.multiprocess
def test_reproduce_says_what_it_cannot_do(tmp_path):
  run = subprocess.run([sys.executable, '-m', 'experiments.evaluate',
                        '--config=configs/evals/reproduce.py', f'--config.data_root={tmp_path}',
                        f'--workdir={tmp_path / "out"}'], cwd=ROOT, capture_output=True,
                       text=True, timeout=300)
  assert run.returncode != 0 and 'Traceback' not in run.stderr
  assert 'nothing to evaluate under' in run.stderr and 'test_oxford' in run.stderr


@pytest.mark.multiprocess
def test_evaluate_names_a_bad_type_and_missing_data(tmp_path):
  common = [sys.executable, '-m', 'experiments.evaluate', '--config=configs/evals/registration.py',
            f'--workdir={tmp_path / "out"}']
  run = subprocess.run(common + ['--config.evals.registration.type=tables'], cwd=ROOT,
                       capture_output=True, text=True, timeout=300)
  assert run.returncode != 0 and 'Traceback' not in run.stderr
  assert 'evals.registration.type must be one of registration, precision' in run.stderr
  run = subprocess.run(common + [f'--config.evals.registration.dataset={tmp_path / "nope"}'],
                       cwd=ROOT, capture_output=True, text=True, timeout=300)
  assert run.returncode != 0 and 'Traceback' not in run.stderr
  assert f'no registration set at {tmp_path / "nope"}' in run.stderr
  empty = registration_config.get_config()
  del empty.evals.registration
  with pytest.raises(ValueError, match='config.evals is empty'):
    evaluators.evaluate(empty, tmp_path / 'out')


@pytest.mark.multiprocess
def test_plot_keypoints_cli(synthetic_root, tmp_path):
  cloud = synthetic_root / 'test_kitti' / '00' / '000000.bin'
  run = subprocess.run([sys.executable, '-m', 'experiments.diagnostics.plot_keypoints',
                        f'--cloud={cloud}', f'--out={tmp_path / "k.png"}', '--sources=iss,random'],
                       cwd=ROOT, capture_output=True, text=True, timeout=300)
  assert run.returncode == 0, run.stderr[-3000:]
  assert 'random: 1024 keypoints' in run.stdout and (tmp_path / 'k.png').stat().st_size > 10_000
  run = subprocess.run([sys.executable, '-m', 'experiments.diagnostics.plot_keypoints',
                        f'--cloud={cloud}', f'--out={tmp_path / "k.png"}', '--sources=iss,learned'],
                       cwd=ROOT, capture_output=True, text=True, timeout=300)
  assert run.returncode != 0 and 'learned keypoints need --checkpoint' in run.stderr
  # A shipped name, as every --checkpoint takes one.
  run = subprocess.run([sys.executable, '-m', 'experiments.diagnostics.plot_keypoints',
                        f'--cloud={cloud}', f'--out={tmp_path / "k.png"}', '--sources=learned',
                        '--checkpoint=ours_detector'], cwd=ROOT, capture_output=True, text=True,
                       timeout=300)
  assert run.returncode == 0, run.stderr[-3000:]
  assert int(run.stdout.split('learned: ')[1].split()[0]) >= 64


@pytest.mark.multiprocess
def test_descriptor_matching_cli_names_a_truncated_cluster(tmp_path):
  good = np.zeros((10, 6), np.float32)
  good[:, :3] = np.random.default_rng(0).normal(size=(10, 3))
  good[:, 5] = 1.0
  good.tofile(tmp_path / '0_0.bin')
  (tmp_path / '0_1.bin').write_bytes(good.tobytes()[:-5])
  (tmp_path / 'filenames.txt').write_text('pair label\n0 1\n')
  run = subprocess.run([sys.executable, '-m', 'experiments.evaluate',
                        '--config=configs/evals/descriptor_matching.py', f'--workdir={tmp_path / "out"}',
                        f'--config.evals.descriptor_matching.clusters={tmp_path}',
                        "--config.evals.descriptor_matching.descriptors=('fpfh',)"],
                       cwd=ROOT, capture_output=True,
                       text=True, timeout=300)
  assert run.returncode != 0 and 'Traceback' not in run.stderr
  assert '0_1.bin' in run.stderr and 'truncated' in run.stderr


# ---- learning curve ------------------------------------------------------------------------

@pytest.mark.multiprocess
@pytest.mark.slow
def test_learning_curve_rows_resume_and_cli(synthetic_root, tiny_checkpoint, tmp_path):
  pairs = registration_sets.read_registration_set(synthetic_root / 'test_oxford')[:2]
  csv_path = tmp_path / 'curve.csv'
  loaded = []

  def load(run, step):
    loaded.append((run, step))
    return inference.load(tiny_checkpoint, step)

  checkpoints = [('tiny', 2), ('tiny', 4)]
  records = learning_curve.run({'oxford': pairs}, checkpoints, load, csv_path, progress=False)
  assert [(r['run'], r['step'], r['row']) for r in records] == [
      ('', '', 'iss+fpfh'), ('tiny', '2', 'iss+ours'), ('tiny', '4', 'iss+ours')]
  assert loaded == checkpoints
  # The FPFH row is the registration table's row on the same pairs.
  store = feature_store.FeatureStore({}, seed=0)
  res = registration.register_pairs(pairs, ['iss+fpfh'], store, progress=False)['iss+fpfh']
  assert float(records[0]['success']) == pytest.approx(100 * np.mean([r['success'] for r in res]))
  assert float(records[0]['trials']) == pytest.approx(np.mean([r['trials'] for r in res]))
  yaws = [registration.yaw_bin(registration.relative_yaw_deg(p.transform)) for p in pairs]
  for b, (lo, hi) in enumerate(registration.YAW_BINS):
    assert int(records[0][f'pairs_yaw_{lo}_{hi}']) == yaws.count(b)
  # The learned row is the registration table's row of that checkpoint.
  store.models['tiny4'] = inference.load(tiny_checkpoint, 4)
  res = registration.register_pairs(pairs, ['iss+tiny4'], store, progress=False)['iss+tiny4']
  assert float(records[2]['trials']) == pytest.approx(np.mean([r['trials'] for r in res]))
  # Finished cells are read back, not recomputed.
  again = learning_curve.run({'oxford': pairs}, checkpoints, load, csv_path, progress=False)
  assert again == records and loaded == checkpoints

  out = tmp_path / 'cli'
  run = subprocess.run(
      [sys.executable, '-m', 'experiments.learning_curve', f'--run=tiny={tiny_checkpoint}',
       f'--out={out}', '--steps=4', f'--set=oxford={synthetic_root / "test_oxford"}',
       '--fpfh_max_nn=50'], cwd=ROOT, capture_output=True, text=True, timeout=900)
  assert run.returncode == 0, run.stderr[-3000:]
  assert (out / 'learning_curve.png').stat().st_size > 10_000
  assert '| oxford | tiny | 4 | iss+ours |' in (out / 'learning_curve.md').read_text()
  bad = subprocess.run(
      [sys.executable, '-m', 'experiments.learning_curve', f'--run={tiny_checkpoint}',
       f'--out={out}', '--steps=3', f'--set=oxford={synthetic_root / "test_oxford"}'],
      cwd=ROOT, capture_output=True, text=True, timeout=300)
  assert bad.returncode != 0 and 'no checkpoint at steps [3]' in bad.stderr
  assert 'Traceback' not in bad.stderr


def test_rotation_sweep_separates_equivariant_and_paper_heads(tiny_checkpoint, tmp_path):
  rng = np.random.default_rng(0)
  points = (rng.uniform(-10, 10, (3000, 3)) * np.array([1, 1, 0.2])).astype(np.float32)
  centers = points[:64]
  paper = orientation.rotation_sweep(inference.load(tiny_checkpoint), points, centers,
                                     [0, 90, 180])
  assert paper[0]['self_match_rate'] == 1.0 and paper[0]['descriptor_distance'] < 1e-5
  assert paper[2]['orientation_error_deg'] > 20 and paper[2]['self_match_rate'] < 0.9
  ours = orientation.rotation_sweep(pretrained.load('ours'), points, centers, [0, 90, 180])
  for r in ours:
    assert r['orientation_error_deg'] < 0.1 and r['self_match_rate'] == 1.0, r


def test_fingerprints_tell_stages_apart(tmp_path):
  a = np.arange(12, dtype=np.float32).reshape(4, 3)
  assert fingerprint.digest([a]) == fingerprint.digest([a.copy()])
  assert len(fingerprint.digest([a])) == 12
  b = a.copy()
  b[2, 1] = np.nextafter(b[2, 1], np.inf, dtype=np.float32)   # one ulp
  assert fingerprint.digest([b]) != fingerprint.digest([a])
  assert fingerprint.digest([a.astype(np.float64)]) != fingerprint.digest([a])
  assert fingerprint.digest([a.reshape(3, 4)]) != fingerprint.digest([a])
  log = tmp_path / 'table_x_pairs.jsonl'
  rows = [{'row': r, 'trials': t, 'inliers': 5, 'rte': 0.1, 'rre': 0.2}
          for r, t in (('iss+fpfh', 10), ('iss+ours', 20), ('iss+fpfh', 30))]
  log.write_text(''.join(json.dumps(r) + '\n' for r in rows))
  first = fingerprint.registration_digests(log)
  assert sorted(first) == ['iss+fpfh', 'iss+ours']
  rows[2]['rte'] = 0.1000001
  log.write_text(''.join(json.dumps(r) + '\n' for r in rows))
  second = fingerprint.registration_digests(log)
  assert second['iss+ours'] == first['iss+ours'] and second['iss+fpfh'] != first['iss+fpfh']
  env = fingerprint.environment()
  assert env['jax'] != 'not installed' and 'cores' in env['cpu']
  assert '| jax |' in fingerprint.markdown({'keypoints: iss': 'abc'}, env)


# ml_collections loads the --config file with importlib's deprecated load_module.
@pytest.mark.filterwarnings('ignore:the load_module:DeprecationWarning')
@pytest.mark.parametrize('error, reported', [
    (errors.UserError('evals.x.dataset: no registration set at /nope'), True),
    (ValueError('operands could not be broadcast together'), False),   # a bug
])
def test_evaluate_reports_user_errors_in_one_line_and_keeps_a_bugs_traceback(
    monkeypatch, tmp_path, error, reported):
  from experiments import evaluate   # pylint: disable=g-import-not-at-top  (its absl flags)
  evaluate.FLAGS(['evaluate', f'--workdir={tmp_path}'])
  monkeypatch.setattr(evaluate.cli, 'initialize_distributed', lambda: None)

  def fail(*args):
    raise error
  monkeypatch.setattr(evaluators, 'evaluate', fail)
  if reported:
    with pytest.raises(SystemExit, match=f'^error: {error}$'):
      evaluate.main(['evaluate'])
  else:
    with pytest.raises(ValueError, match='could not be broadcast'):
      evaluate.main(['evaluate'])


@pytest.mark.real_data
@pytest.mark.slow
def test_feature_store_shares_work_between_rows_and_changes_no_result(tmp_path):
  """FPFH of two keypoint sets described together, and learned clusters shared by models
  of one setting: each equals what the row computes alone."""
  scan = io.read_cloud(shared_path('kitti_object_velodyne', '000000.bin')).astype(np.float64)
  scan = scan[np.linalg.norm(scan[:, :2], axis=1) < 30]
  scan, _ = cloud_features.to_grid(scan, 0.2)   # as every test set: FPFH over the cloud itself
  turn = geometry.make_transform(geometry.rotation_z(np.radians(30.0)), np.array([2.0, 1.0, 0.0]))
  paths = [str(tmp_path / 'a.npy'), str(tmp_path / 'b.npy')]
  np.save(paths[0], scan.astype(np.float32))
  np.save(paths[1], ((scan - turn[:3, 3]) @ turn[:3, :3]).astype(np.float32))
  model = pretrained.load('ours')
  store = feature_store.FeatureStore({'ours': model, 'twin': dataclasses.replace(model)})
  store.describe_fpfh_together(['iss+fpfh', 'auto+fpfh+upright'])
  points = store.cloud(paths[0])
  for kp in ('iss', 'auto'):
    np.testing.assert_array_equal(store.features(paths[0], f'{kp}+fpfh').descriptors,
                                  features.fpfh(points, store.keypoints(paths[0], kp)))
  ours, twin = (store.features(paths[0], f'iss+{m}').descriptors for m in ('ours', 'twin'))
  np.testing.assert_array_equal(ours, inference.describe(
      model, points, points[store.keypoints(paths[0], 'iss')]))
  np.testing.assert_array_equal(ours, twin)
  assert len(store._clusters) == 1   # the twin's clusters were the first model's



@pytest.mark.real_data
@pytest.mark.slow
def test_rows_of_the_register_command_register_as_the_command_does(tmp_path):
  """Every row that verifies (the README's "defaults" rows) and each `COMMAND_ROWS` name
  runs `pipeline.Registrar`: per pair, the errors, trials, inliers and verdict of the
  pose `register_many` gives the same files with the same options."""
  scan = io.read_cloud(shared_path('kitti_object_velodyne', '000000.bin')).astype(np.float64)
  scan = scan[np.linalg.norm(scan[:, :2], axis=1) < 40]
  paths, pairs = [str(tmp_path / 'a.npy')], []
  np.save(paths[0], scan[::2])
  for n, (yaw, shift) in enumerate(((40.0, [3.0, -2.0, 0.1]), (-120.0, [-4.0, 1.0, 0.0]))):
    t = geometry.make_transform(geometry.rotation_z(np.radians(yaw)), np.array(shift))
    paths.append(str(tmp_path / f'{n}.npy'))
    np.save(paths[-1], (scan[1::2] - t[:3, 3]) @ t[:3, :3])
    pairs.append(registration_sets.RegistrationPair('x', 0, n + 1, paths[0], paths[-1], t))
  ours, default = pretrained.load('ours'), pretrained.load(pretrained.DEFAULT)
  rows = {'auto+ours+upright+verify+bev': (options_lib.Options(), ours),
          'register_fpfh': (options_lib.Options(descriptor='fpfh'), None),
          'register_descriptor': (options_lib.Options(verify=0, bev=0), default)}
  results = registration.register_pairs(pairs, list(rows), feature_store.FeatureStore(
      {'ours': ours, pretrained.DEFAULT: default}), progress=False)
  for row, (options, m) in rows.items():
    command = pipeline.register_many([(p.cloud1, p.cloud2) for p in pairs], clean.read_metres,
                                     model=m, options=options, say=lambda line: None)
    for pair, got, want in zip(pairs, results[row], command):
      reg = want.registration
      expected = {**metrics.registration_errors(pair.transform, reg.transform),
                  'trials': reg.trials, 'inliers': int(reg.inliers.sum()),
                  **reg.verdict.to_json()}
      assert {k: got[k] for k in expected} == expected, row
      assert got['success'], (row, got)


def test_a_command_row_describes_with_the_models_own_keypoints():
  # An adapted export may keep its keypoints on the structure (`experiments.adapt`): the
  # register command samples them there, and so does its row; a named row says its own.
  adapted = dataclasses.replace(pretrained.load('ours'), keypoints='structure')
  for row, want in (('register', 'structure'), ('register_descriptor', 'structure'),
                    ('auto+ours+upright+verify+bev', 'all'),
                    ('structure+ours+upright+verify+bev', 'structure')):
    _, model = feature_store.command_options(row, {'ours': adapted,
                                                   pretrained.DEFAULT: adapted})
    assert model.keypoints == want, row
    assert cloud_features.domain_of(model) == want, row


def test_feature_store_takes_as_many_farthest_point_keypoints_as_asked(tmp_path):
  rng = np.random.default_rng(0)
  cloud = rng.uniform(-30, 30, (5000, 3)).astype(np.float32)
  cloud[:, 2] *= 0.1
  path = tmp_path / 'cloud.npy'
  np.save(path, cloud)
  default = feature_store.FeatureStore({}).keypoints(path, 'auto')
  fewer = feature_store.FeatureStore({}, num_keypoints=200).keypoints(path, 'auto')
  assert len(default) == 1024 and len(fewer) == 200
  # Farthest-point picks continue one sampling: the 200 are the first 200 of the 1,024.
  assert set(fewer.tolist()) <= set(default.tolist())
  with pytest.raises(errors.UserError, match='num_keypoints must be a whole number >= 3'):
    feature_store.FeatureStore({}, num_keypoints=0)


def test_register_pairs_refuses_an_unknown_sampling_before_any_pair():
  # A wrong value must stop the evaluation in one line, not fail every pair as a
  # ValueError from `pair_stages.estimate` would.
  with pytest.raises(errors.UserError, match="sampling must be one of .*got 'guided'"):
    registration.register_pairs([], ['auto+fpfh+upright'], feature_store.FeatureStore({}),
                                progress=False, sampling='guided')
