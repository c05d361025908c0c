"""Registration entry points on a tiny synthetic set: readers, register, evaluate."""

import csv
import json
import os
import subprocess
import sys

import laspy
import numpy as np
import open3d as o3d
import pytest

from ssd_jax import geometry, pretrained
from ssd_jax.data import io, registration_sets
from ssd_jax.registration import metrics
from ssd_jax.registration import options as options_lib
from ssd_jax.synthetic import degenerate
from tests.conftest import shared_path

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture
def tiny_set(synthetic_root):
  return synthetic_root


def _run(*args):
  return subprocess.run([sys.executable, '-m', *args], cwd=ROOT, capture_output=True, text=True,
                        timeout=600)


def test_readers_of_both_layouts(tiny_set):
  kitti = registration_sets.read_registration_set(tiny_set / 'test_kitti')
  single = registration_sets.read_registration_set(tiny_set / 'test_kitti' / '00')
  oxford = registration_sets.read_registration_set(tiny_set / 'test_oxford')
  assert len(kitti) == len(single) >= 5 and len(oxford) >= 5
  assert kitti[0].cloud1.name == f'{kitti[0].idx1:06d}.bin' and kitti[0].sequence == '00'
  assert oxford[0].cloud1.parent.name == 'test_models'
  with pytest.raises(io.CloudFileError, match='no groundtruths.txt here'):
    registration_sets.read_registration_set(tiny_set / 'train')


@pytest.mark.multiprocess
def test_register_cli_fpfh_on_a_synthetic_pair(tiny_set, tmp_path):
  folder = tiny_set / 'test_kitti' / '00'
  pair = registration_sets.read_registration_set(folder)[0]
  out = _run('experiments.register', f'--cloud1={pair.cloud1}', f'--cloud2={pair.cloud2}',
             f'--groundtruth={folder / "groundtruths.txt"}', f'--json={tmp_path / "new" / "r.json"}',
             f'--plot={tmp_path / "r.png"}', '--descriptor=fpfh', '--fpfh_max_nn=200')
  assert out.returncode == 0, out.stderr[-3000:]
  result = json.loads((tmp_path / 'new' / 'r.json').read_text())
  t = np.array(result['T_12'])
  assert t.shape == (4, 4) and result['errors']['success'], result
  np.testing.assert_allclose(t[:3, 3], pair.transform[:3, 3], atol=1.0)
  assert result['inliers'] >= 3 and result['trials'] >= 10
  assert (tmp_path / 'r.png').stat().st_size > 10_000
  assert 'vs ground truth: RTE' in out.stdout


@pytest.mark.multiprocess
@pytest.mark.slow
def test_register_cli_errors(tiny_set, tmp_path):
  cloud = tiny_set / 'test_kitti' / '00' / '000000.bin'
  out = _run('experiments.register', f'--cloud1={cloud}', f'--cloud2={tmp_path / "nope.bin"}')
  assert out.returncode != 0 and 'nope.bin: no such file' in out.stderr
  assert 'Traceback' not in out.stderr
  out = _run('experiments.register', f'--cloud1={cloud}', f'--cloud2={cloud}',
             '--descriptor=learned', f'--checkpoint={tmp_path / "none"}')
  assert out.returncode != 0 and 'none: no such checkpoint directory' in out.stderr
  assert 'Traceback' not in out.stderr
  out = _run('experiments.register', f'--cloud1={cloud}', f'--cloud2={cloud}',
             '--descriptor=learned', '--draws=-2')
  assert out.returncode != 0 and "draws must be >= 0 (0: the model's own), got -2" in out.stderr
  assert 'Traceback' not in out.stderr
  # An output path that cannot be written fails before the work, not after it.
  (tmp_path / 'a_file').write_text('')
  out = _run('experiments.register', f'--cloud1={cloud}', f'--cloud2={cloud}',
             f'--json={tmp_path / "a_file" / "r.json"}')
  assert out.returncode != 0 and 'cannot create the folder of' in out.stderr
  assert '==' not in out.stdout and 'Traceback' not in out.stderr
  out = _run('experiments.register', f'--cloud1={cloud}', f'--cloud2={cloud}', '--format=xyzq')
  assert out.returncode != 0 and 'Traceback' not in out.stderr
  # The BEV search's poses turn about z only: asked for with rigid RANSAC, it is refused.
  out = _run('experiments.register', f'--cloud1={cloud}', f'--cloud2={cloud}', '--ransac=rigid',
             '--bev=3')
  assert out.returncode != 0 and out.stderr.strip().splitlines()[-1] == (
      'error: --bev needs --ransac=upright and --verify > 0 (its poses turn about z only, and '
      "are checked with RANSAC's)")


@pytest.mark.multiprocess
@pytest.mark.slow
def test_register_cli_describes_with_the_shipped_model_by_default(tiny_set, tmp_path):
  """No --descriptor, no --checkpoint: the shipped default model describes, the pair registers."""
  folder = tiny_set / 'test_kitti' / '00'
  pair = registration_sets.read_registration_set(folder)[0]
  out = _run('experiments.register', f'--cloud1={pair.cloud1}', f'--cloud2={pair.cloud2}',
             f'--groundtruth={folder / "groundtruths.txt"}',
             f'--json={tmp_path / "r.json"}')
  assert out.returncode == 0, out.stderr[-3000:]
  result = json.loads((tmp_path / 'r.json').read_text())
  assert result['descriptor'] == 'learned' and result['model'] == pretrained.DEFAULT
  assert result['keypoints'] == 'auto' and result['keypoint_domain'] == 'all'   # its own: all
  # Verified poses: one sampling of 32 points of each ball (an eighth of the network's
  # work), not the model's own 4 of 64 (the paper's protocol).
  assert result['draws'] == options_lib.VERIFIED_DRAWS == 1
  assert result['num_samples'] == options_lib.VERIFIED_SAMPLES == 32
  default = pretrained.load(pretrained.DEFAULT)
  assert (default.draws, default.num_samples) == (4, 64)
  assert result['errors']['success'], result
  # --draws=0: the model's own setting; the same pair registers alike.
  out = _run('experiments.register', f'--cloud1={pair.cloud1}', f'--cloud2={pair.cloud2}',
             '--descriptor=learned', '--draws=0', f'--groundtruth={folder / "groundtruths.txt"}',
             f'--json={tmp_path / "r4.json"}')
  assert out.returncode == 0, out.stderr[-3000:]
  four = json.loads((tmp_path / 'r4.json').read_text())
  assert four['draws'] == 4 and four['num_samples'] == 64
  assert four['errors']['success'] and four['T_12'] != result['T_12']


@pytest.mark.multiprocess
def test_evaluate_registration_rows_and_missing_models(tiny_set, tmp_path):
  out = _run('experiments.evaluate', f'--workdir={tmp_path}',
             f'--config.evals.registration.dataset={tiny_set / "test_kitti"}',
             '--config.max_pairs=3',
             "--config.rows=('iss+fpfh','iss+ours')", f'--config.checkpoints.ours={tmp_path / "x"}',
             '--config.fpfh_max_nn=200')
  assert out.returncode == 0, out.stderr[-3000:]
  md = (tmp_path / 'registration.md').read_text()
  assert '| ISS kpt + FPFH desc | 3 |' in md
  assert '| ISS kpt + Ours desc | missing |' in md and 'no such checkpoint directory' in md
  lines = [json.loads(l) for l in (tmp_path / 'registration_pairs.jsonl').read_text().splitlines()]
  assert len(lines) == 3 and all(l['row'] == 'iss+fpfh' for l in lines)
  assert (tmp_path / 'registration.csv').read_text().count('\n') == 3


@pytest.mark.real_data
@pytest.mark.multiprocess
@pytest.mark.parametrize('names,descriptor', [
    (('oxford_270', 'oxford_456'), 'learned'), (('kitti_00_001554', 'kitti_00_004534'), 'learned'),
    (('kitti_00_001554', 'kitti_00_004534'), 'fpfh')])
@pytest.mark.slow
def test_register_cli_on_real_pairs(names, descriptor, tmp_path):
  """The real pairs have no ground truth: the RANSAC pose must be a success (RTE < 2 m,
  RRE < 5°) against the ICP-refined pose, and most points of cloud 2 must land on cloud 1.
  The learned rows use the shipped model."""
  c1, c2 = (shared_path('example', f'{n}.bin') for n in names)
  common = [f'--cloud1={c1}', f'--cloud2={c2}', f'--descriptor={descriptor}', '--fpfh_max_nn=200']
  out = _run('experiments.register', *common, f'--json={tmp_path / "ransac.json"}')
  assert out.returncode == 0, out.stderr[-3000:]
  out = _run('experiments.register', *common, '--icp', f'--json={tmp_path / "icp.json"}')
  assert out.returncode == 0, out.stderr[-3000:]
  ransac_t = np.array(json.loads((tmp_path / 'ransac.json').read_text())['T_12'])
  icp = json.loads((tmp_path / 'icp.json').read_text())
  err = metrics.registration_errors(np.array(icp['T_12']), ransac_t)
  assert icp['icp_fitness'] > 0.8 and icp['overlap_fitness'] > 0.7
  assert err['success'] and err['rte'] < 1.0, err


_FUZZ_DRIVER = '''
import json, sys
from absl import flags
from experiments import register
from ssd_jax.infra import cli
results = []
for args in json.loads(sys.argv[1]):
  flags.FLAGS.unparse_flags()
  flags.FLAGS(['register', *args])
  try:
    cli.one_line_errors(register.main)(['register'])
    results.append({'code': 0})
  except SystemExit as e:
    results.append({'code': e.code if isinstance(e.code, int) else 1, 'message': str(e.code)})
print(json.dumps(results))
'''


@pytest.mark.multiprocess
@pytest.mark.slow
def test_register_fuzz_bad_files_fail_in_one_line_or_register_correctly(tiny_set, tmp_path):
  """A table of damaged, odd and far-away files through `register` (one process): each
  ends in a one-line error or in a correct transform, never in exit 0 with a wrong one."""
  pair = registration_sets.read_registration_set(tiny_set / 'test_kitti')[0]
  c1, c2 = (io.read_cloud(p).astype(np.float64) for p in (pair.cloud1, pair.cloud2))
  rng = np.random.default_rng(0)
  utm = np.array([4.5e5, 5.4e6, 30.0])

  def write(name, data):
    path = tmp_path / name
    if name.endswith('.npy'):
      np.save(path, data)
    elif name.endswith('.ply'):
      o3d.io.write_point_cloud(str(path), o3d.geometry.PointCloud(o3d.utility.Vector3dVector(data)))
    elif isinstance(data, bytes):
      path.write_bytes(data)
    else:
      data.tofile(path)
    return str(path)

  good = write('good.bin', c1.astype('<f4'))
  bad = {   # name -> (cloud 1, the one-line message expected)
      'empty.bin': (write('empty.bin', b''), 'file is empty'),
      'cut.bin': (write('cut.bin', c1.astype('<f4').tobytes()[:-2]), 'not a whole number'),
      'noise.bin': (write('noise.bin', rng.integers(0, 256, 48_000, np.uint8).tobytes()),
                    'fit no .bin layout'),
      'far32.bin': (write('far32.bin', (c1 + 2e7).astype('<f4')), 'float32 resolves only 2 m'),
      'nan.npy': (write('nan.npy', np.full((100, 3), np.nan)), 'no finite points'),
      'flat.npy': (write('flat.npy', np.zeros((100, 2))), 'expected an [N, >=3] array'),
      'same.npy': (write('same.npy', np.ones((100, 3))), 'all 100 points coincide'),
      'few.npy': (write('few.npy', c1[:5]), 'keypoints: found'),
      'plane.npy': (write('plane.npy', np.c_[rng.uniform(-20, 20, (5000, 2)), np.zeros(5000)]),
                    'keypoints: found'),
      'scan.e57': (write('scan.e57', b'1 2 3\n'), 'unsupported file type'),
      'words.txt': (write('words.txt', b'poses of the drive\n'), 'no line of three or more'),
      'one.txt': (write('one.txt', b'1 2 3\n'), 'all 1 points coincide'),
  }
  good_pairs = {   # name -> (cloud 1, cloud 2, T_12 expected)
      'float64 rows': (write('a64.bin', c1.astype('<f8')), write('b64.bin', c2.astype('<f8')),
                       pair.transform),
      'intensity 0-255': (write('ai.bin', np.c_[c1, rng.uniform(0, 255, len(c1))].astype('<f4')),
                          write('bi.bin', np.c_[c2, rng.uniform(0, 255, len(c2))].astype('<f4')),
                          pair.transform),
      'text .xyz, .csv': (write('a.xyz', b'\n'.join(b' '.join(b'%.6f' % v for v in p)
                                                    for p in c1)),
                          write('b.csv', b'x,y,z\n' + b'\n'.join(b','.join(b'%.6f' % v for v in p)
                                                                 for p in c2)),
                          pair.transform),
      'UTM .ply': (write('a.ply', c1 + utm), write('b.ply', c2 + utm),
                   geometry.make_transform(np.eye(3), utm) @ pair.transform @
                   geometry.make_transform(np.eye(3), -utm)),
  }
  cases = [[f'--cloud1={path}', f'--cloud2={good}', '--descriptor=fpfh'] for path, _ in bad.values()]
  cases += [[f'--cloud1={a}', f'--cloud2={b}', f'--json={tmp_path / f"{i}.json"}',
             '--descriptor=fpfh', '--fpfh_max_nn=200'] for i, (a, b, _) in enumerate(good_pairs.values())]
  run = subprocess.run([sys.executable, '-c', _FUZZ_DRIVER, json.dumps(cases)], cwd=ROOT,
                       capture_output=True, text=True, timeout=900)
  assert run.returncode == 0, run.stderr[-3000:]
  results = json.loads(run.stdout.strip().splitlines()[-1])
  for (name, (_, message)), result in zip(bad.items(), results):
    assert result['code'] != 0, name
    assert result['message'].startswith('error: ') and message in result['message'], (name, result)
    assert '\n' not in result['message'], name
  for i, ((name, (_, b, t_gt)), result) in enumerate(zip(good_pairs.items(), results[len(bad):])):
    assert result['code'] == 0, (name, result)
    t = np.array(json.loads((tmp_path / f'{i}.json').read_text())['T_12'])
    src = io.read_cloud(b).astype(np.float64)
    moved = lambda m: src @ m[:3, :3].T + m[:3, 3]
    err = np.linalg.norm(moved(t) - moved(t_gt), axis=1)
    assert np.median(err) < 0.5 and err.max() < 2.0, (name, np.median(err), err.max())


@pytest.mark.multiprocess
@pytest.mark.slow
def test_the_compilation_cache_keeps_kernels_and_changes_no_result(tiny_set, tmp_path):
  pair = registration_sets.read_registration_set(tiny_set / 'test_kitti' / '00')[0]
  args = ['experiments.register', f'--cloud1={pair.cloud1}', f'--cloud2={pair.cloud2}',
          '--descriptor=learned']
  results = []
  for n, cache in enumerate((tmp_path / 'cache', tmp_path / 'cache', '')):
    out = _run(*args, f'--compilation_cache={cache}', f'--json={tmp_path / f"{n}.json"}')
    assert out.returncode == 0, out.stderr[-3000:]
    results.append(json.loads((tmp_path / f'{n}.json').read_text()))
    if n == 0:
      kept = sorted(p.name for p in (tmp_path / 'cache').iterdir())
      assert len(kept) >= 2, kept   # the descriptor network's kernels, at least
  assert sorted(p.name for p in (tmp_path / 'cache').iterdir()) == kept   # loaded, not rebuilt
  # The same descriptors, RANSAC, BEV search and verification: T bit for bit.
  for r in results[1:]:
    assert r['inliers'] == results[0]['inliers'] and r['trials'] == results[0]['trials']
    np.testing.assert_array_equal(r['T_12'], results[0]['T_12'])


@pytest.mark.multiprocess
@pytest.mark.slow
def test_batch_mode_registers_a_sequence_and_a_pair_list(tiny_set, tmp_path):
  folder = tiny_set / 'test_kitti' / '00'
  scans = sorted(folder.glob('*.bin'))[:4]
  seq = tmp_path / 'scans'
  seq.mkdir()
  for p in scans:
    (seq / p.name).write_bytes(p.read_bytes())
  out = _run('experiments.register', f'--sequence={seq}', f'--out={tmp_path / "seq"}',
             f'--groundtruth={folder / "groundtruths.txt"}', '--descriptor=fpfh', '--fpfh_max_nn=200')
  assert out.returncode == 0, out.stderr[-3000:]
  rows = list(csv.DictReader((tmp_path / 'seq' / 'registrations.csv').open()))
  assert [(r['cloud1'], r['cloud2']) for r in rows] == [
      (str(a), str(b)) for a, b in zip(sorted(seq.glob('*.bin'))[:-1], sorted(seq.glob('*.bin'))[1:])]
  poses = np.loadtxt(tmp_path / 'seq' / 'poses.txt').reshape(-1, 3, 4)
  assert poses.shape == (4, 3, 4)
  np.testing.assert_allclose(poses[0], np.eye(4)[:3])
  t01 = np.array([float(rows[0][f'T_12[{i}][{j}]']) for i in range(4) for j in range(4)])
  np.testing.assert_allclose(poses[1], t01.reshape(4, 4)[:3])   # P_1 = P_0 T_01
  listed = registration_sets.read_registration_set(folder)[0]            # the ground truth lists it
  assert rows[0]['success'] == ('True' if listed.idx2 == 1 else '')
  assert (tmp_path / 'seq' / 'trajectory.png').stat().st_size > 10_000
  # A pair list: paths relative to the list; a malformed line is one line of error.
  (tmp_path / 'pairs.txt').write_text(f'# first pair\n{listed.cloud1} {listed.cloud2}\n')
  out = _run('experiments.register', f'--pairs={tmp_path / "pairs.txt"}',
             f'--out={tmp_path / "list"}', f'--groundtruth={folder / "groundtruths.txt"}',
             '--descriptor=fpfh', '--fpfh_max_nn=200')
  assert out.returncode == 0, out.stderr[-3000:]
  (row,) = csv.DictReader((tmp_path / 'list' / 'registrations.csv').open())
  assert row['success'] == 'True' and int(row['inliers']) >= 3
  (tmp_path / 'bad.txt').write_text('a.bin b.bin c.bin\n')
  out = _run('experiments.register', f'--pairs={tmp_path / "bad.txt"}', f'--out={tmp_path / "x"}')
  assert out.returncode == 1
  assert out.stderr.strip().splitlines()[-1] == (
      f"error: {tmp_path / 'bad.txt'}, line 1: expected \"cloud1 cloud2\", got 'a.bin b.bin c.bin'")


@pytest.mark.multiprocess
@pytest.mark.slow
def test_las_and_laz_register_like_the_same_points_in_ply(tiny_set, tmp_path):
  pair = registration_sets.read_registration_set(tiny_set / 'test_kitti')[0]
  offset = np.array([500_000.0, 4_000_000.0, 100.0])   # UTM-like map coordinates
  for k, cloud in enumerate((pair.cloud1, pair.cloud2)):
    pts = io.read_cloud(cloud).astype(np.float64) + offset
    header = laspy.LasHeader(point_format=3, version='1.2')
    header.offsets, header.scales = offset, [0.0001] * 3
    las = laspy.LasData(header)
    las.x, las.y, las.z = pts.T
    for ext in ('las', 'laz'):
      las.write(tmp_path / f'c{k}.{ext}')
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(io.read_cloud(tmp_path / f'c{k}.las')))
    o3d.io.write_point_cloud(str(tmp_path / f'c{k}.ply'), pcd)
  results = {}
  for ext in ('las', 'laz', 'ply'):
    out = _run('experiments.register', f'--cloud1={tmp_path / f"c0.{ext}"}',
               f'--cloud2={tmp_path / f"c1.{ext}"}', f'--json={tmp_path / f"{ext}.json"}',
               '--descriptor=fpfh', '--fpfh_max_nn=200')
    assert out.returncode == 0, out.stderr[-3000:]
    results[ext] = json.loads((tmp_path / f'{ext}.json').read_text())
  np.testing.assert_allclose(results['las']['T_12'], results['ply']['T_12'], atol=1e-6)
  np.testing.assert_allclose(results['laz']['T_12'], results['ply']['T_12'], atol=1e-6)
  # In map coordinates: T_12 = offset o (the true local transform) o -offset.
  t = np.array(results['las']['T_12'])
  shift = geometry.make_transform(np.eye(3), offset)
  local = np.linalg.inv(shift) @ t @ shift
  assert metrics.registration_errors(pair.transform, local)['success']
  # What Open3D's RegistrationResult carries, beside T_12.
  r = results['las']
  assert 0 < r['fitness'] <= 1 and 0 < r['inlier_rmse'] < 1 and r['correspondence_set_size'] >= 3


@pytest.mark.multiprocess
@pytest.mark.slow
def test_register_puts_dense_clouds_on_the_grid_and_voxel_0_keeps_every_point(tiny_set, tmp_path):
  pair = registration_sets.read_registration_set(tiny_set / 'test_kitti')[0]
  rng = np.random.default_rng(0)
  paths = []
  for n, path in enumerate((pair.cloud1, pair.cloud2)):
    pts = io.read_cloud(path)
    dense = np.repeat(pts, 8, axis=0) + rng.normal(0, 0.03, (8 * len(pts), 3)).astype(np.float32)
    paths.append(tmp_path / f'dense{n}.bin')
    dense.astype(np.float32).tofile(paths[-1])
  counts = [8 * len(io.read_cloud(p)) for p in (pair.cloud1, pair.cloud2)]
  for voxel, name in ((None, 'grid'), (0, 'all')):
    out = _run('experiments.register', f'--cloud1={paths[0]}', f'--cloud2={paths[1]}',
               f'--json={tmp_path / name}.json', '--descriptor=fpfh', '--fpfh_max_nn=200',
               *([] if voxel is None else [f'--voxel={voxel}', '--verify=0']))
    assert out.returncode == 0, out.stderr[-3000:]
    result = json.loads((tmp_path / f'{name}.json').read_text())
    assert metrics.registration_errors(pair.transform, np.array(result['T_12']))['success']
    if voxel is None:
      lines = [l for l in out.stdout.splitlines() if l.startswith('voxel: dense0.bin')]
      assert lines == [f'voxel: dense0.bin: {counts[0]:,} -> {result["points"][0]:,} points on '
                       'the 0.2 m grid'], out.stdout
      assert result['voxel'] == 0.2 and max(result['points']) < counts[0] / 3
      # RANSAC's distinct best poses (up to 10) and the BEV search's 5 checked against the
      # clouds, the best kept.
      assert 6 <= len(result['verified_fitness']) <= 15
      assert max(result['verified_fitness']) > 0.5
    else:
      assert result['voxel'] == 0 and result['points'] == counts
      assert 'voxel:' not in out.stdout and 'verified_fitness' not in result
  # Piped output carries no progress bar unless asked.
  assert 'stage' not in out.stderr and '\r' not in out.stderr
  bad = _run('experiments.register', f'--cloud1={paths[0]}', f'--cloud2={paths[1]}', '--voxel=-1')
  assert bad.returncode != 0 and bad.stderr.strip() == \
      'error: voxel must be >= 0 (0: every point as given), got -1.0'
  bad = _run('experiments.register', f'--cloud1={paths[0]}', f'--cloud2={paths[1]}', '--verify=-2')
  assert bad.returncode != 0 and bad.stderr.strip() == \
      'error: verify must be >= 0 (0: no verification), got -2'


def test_a_cloud_too_large_for_memory_fails_in_one_line(tiny_set, monkeypatch):
  pair = registration_sets.read_registration_set(tiny_set / 'test_kitti')[0]
  assert len(io.read_cloud(pair.cloud1)) > 1000
  monkeypatch.setattr(io, 'available_memory', lambda: 100_000)
  with pytest.raises(io.CloudFileError, match=r'000000.bin: ~[\d,]+ points need ~0.\d GiB to read '
                     r'and put on a grid, 0.0 GiB is available; split it into tiles'):
    io.read_cloud(pair.cloud1)


@pytest.mark.multiprocess
@pytest.mark.slow
def test_a_corridor_comes_back_not_registered_naming_its_free_direction(tmp_path):
  """Two scans 5 m apart along a straight corridor: the pose comes back with the verdict
  `registered: false`, degenerate, naming the shift along it, in the summary line and the
  JSON (with the information matrix); the command ends 0: the pose is an answer, the
  verdict says not to trust it."""
  cloud1, cloud2, _ = degenerate.scan_pair('corridor')
  np.save(tmp_path / 'a.npy', cloud1)
  np.save(tmp_path / 'b.npy', cloud2)
  out = _run('experiments.register', f'--cloud1={tmp_path / "a.npy"}',
             f'--cloud2={tmp_path / "b.npy"}', f'--json={tmp_path / "r.json"}')
  assert out.returncode == 0, out.stderr[-2000:]
  (summary,) = [line for line in out.stdout.splitlines() if line.startswith('== ')]
  assert summary.endswith(')') and ': NOT registered (degenerate: translation along (1.00, ' in (
      summary), summary
  result = json.loads((tmp_path / 'r.json').read_text())
  assert result['registered'] is False
  assert result['verdict']['reason'].startswith('degenerate: translation along (1.00, ')
  assert result['uncertainty']['free'].startswith('translation along (1.00, ')
  assert np.array(result['uncertainty']['information_matrix']).shape == (6, 6)


@pytest.mark.multiprocess
def test_a_cloud_in_millimetres_or_centimetres_gets_a_units_hint(tiny_set, tmp_path):
  pair = registration_sets.read_registration_set(tiny_set / 'test_kitti')[0]
  for unit, scale, hint in (('mm', 1000, 'its points lie ~'), ('cm', 100, 'it spans ')):
    np.save(tmp_path / f'{unit}.npy', io.read_cloud(pair.cloud2).astype(np.float64) * scale)
    out = _run('experiments.register', f'--cloud1={pair.cloud1}',
               f'--cloud2={tmp_path / f"{unit}.npy"}')
    assert out.returncode == 1 and out.stderr.strip().count('\n') == 0, out.stderr[-2000:]
    assert out.stderr.startswith(f'error: {tmp_path / f"{unit}.npy"}: {hint}'), out.stderr
    assert 'centimetres? ssd_jax reads metres' in out.stderr


@pytest.mark.multiprocess
@pytest.mark.slow
def test_a_batch_registers_every_pair_it_can_and_a_rerun_resumes(tiny_set, tmp_path):
  """Three pairs, the second naming a missing file: the first and third registered (their
  verdict too), the second's row holds the error, the command ends non-zero naming one
  failed pair. Once the file exists, a rerun registers only that pair, and the command
  counts the poses registered. --stop_on_error stops at it."""
  pairs = registration_sets.read_registration_set(tiny_set / 'test_kitti' / '00')[:2]
  missing = tmp_path / 'later.bin'
  (tmp_path / 'pairs.txt').write_text(f'{pairs[0].cloud1} {pairs[0].cloud2}\n'
                                      f'{pairs[0].cloud1} {missing}\n'
                                      f'{pairs[1].cloud1} {pairs[1].cloud2}\n')
  args = ('experiments.register', f'--pairs={tmp_path / "pairs.txt"}', f'--out={tmp_path / "out"}')
  out = _run(*args)
  assert out.returncode == 1
  assert out.stderr.strip().splitlines()[-1].startswith('error: 1 of 3 pairs failed')
  rows = list(csv.DictReader((tmp_path / 'out' / 'registrations.csv').open()))
  assert [r['cloud2'] for r in rows] == [str(pairs[0].cloud2), str(missing), str(pairs[1].cloud2)]
  assert not rows[0]['error'] and not rows[2]['error'] and str(missing) in rows[1]['error']
  for row, pair in ((rows[0], pairs[0]), (rows[2], pairs[1])):
    t = np.array([float(row[f'T_12[{i}][{j}]']) for i in range(4) for j in range(4)]).reshape(4, 4)
    assert metrics.registration_errors(pair.transform, t)['success']
    assert float(row['translation_constraint']) > 0 and not row['degenerate']
    assert row['registered'] == '1' and not row['verdict'] and float(row['structure_fitness']) > 0.5
    assert np.array([float(row[f'information[{i}][{j}]']) for i in range(6)
                     for j in range(6)]).reshape(6, 6)[3, 3] > 1000
  missing.write_bytes(pairs[0].cloud2.read_bytes())
  out = _run(*args)
  assert out.returncode == 0, out.stderr[-2000:]
  assert '3 pairs (2 kept from an earlier run)' in out.stdout
  assert ': 3 registered, 0 not (the verdict column says why)' in out.stdout
  again = list(csv.DictReader((tmp_path / 'out' / 'registrations.csv').open()))
  assert again[:2] == [rows[0], rows[2]] and not again[2]['error']
  missing.unlink()
  out = _run(*args[:2], f'--out={tmp_path / "stop"}', '--stop_on_error')
  assert out.returncode == 1 and str(missing) in out.stderr.strip().splitlines()[-1]
  assert len(list(csv.DictReader((tmp_path / 'stop' / 'registrations.csv').open()))) == 1
