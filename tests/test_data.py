import numpy as np
import open3d as o3d
import pytest
from scipy import stats

from ssd_jax.data import clean, datasets, io
from tests.conftest import shared_path


@pytest.mark.real_data
def test_reads_real_3dfeatnet_and_kitti_formats():
  oxford = shared_path('example', 'oxford_270.bin')
  kitti = shared_path('kitti_object_velodyne', '000000.bin')
  assert io.detect_bin_format(np.fromfile(oxford, '<f4'), oxford) == 'xyzn'
  assert io.detect_bin_format(np.fromfile(kitti, '<f4'), kitti) == 'xyzi'
  # 3DFeat-Net's KITTI processing leaves ~20 % of the normals shorter than 1.
  processed = shared_path('example', 'kitti_00_004534.bin')
  assert io.read_cloud(processed).shape == (30609, 3)
  pts = io.read_cloud(oxford)
  assert pts.shape == (16384, 3) and pts.dtype == np.float32
  raw = np.fromfile(kitti, '<f4').reshape(-1, 4)
  np.testing.assert_array_equal(io.read_cloud(kitti), raw[:, :3])


def test_plain_xyz_npy_ply_pcd(tmp_path):
  pts = np.random.default_rng(0).normal(size=(101, 3)).astype(np.float32)
  pts.tofile(tmp_path / 'a.bin')
  np.testing.assert_array_equal(io.read_cloud(tmp_path / 'a.bin', 'xyz'), pts)
  np.save(tmp_path / 'a.npy', pts)
  np.testing.assert_array_equal(io.read_cloud(tmp_path / 'a.npy'), pts)
  pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts.astype(np.float64)))
  for suffix in ('.ply', '.pcd'):
    o3d.io.write_point_cloud(str(tmp_path / f'a{suffix}'), pcd)
    np.testing.assert_allclose(io.read_cloud(tmp_path / f'a{suffix}'), pts, atol=1e-6)


def test_text_and_vtk_clouds(tmp_path):
  """Text clouds whatever their separator, header or extra columns, and legacy VTK in
  ASCII and binary, read to the precision they were written with; broken ones named."""
  rng = np.random.default_rng(1)
  pts = rng.normal(0, 10, (200, 3))
  np.savetxt(tmp_path / 'a.xyz', pts)
  np.savetxt(tmp_path / 'b.csv', np.c_[rng.random(200), pts], delimiter=',',
             header='intensity,X,Y,Z', comments='')   # x, y, z named after another column
  (tmp_path / 'c.pts').write_text('200\n' + '\n'.join(
      ' '.join(f'{v:.9f}' for v in row) + ' 7 0.5' for row in pts))
  (tmp_path / 'd.txt').write_text('\n'.join(';'.join(repr(float(v)) for v in row) for row in pts))
  head = '# vtk DataFile Version 3.0\nscan\n{}\nDATASET POLYDATA\nPOINTS 200 {}\n'
  (tmp_path / 'e.vtk').write_text(head.format('ASCII', 'double') + '\n'.join(
      ' '.join(repr(float(v)) for v in row) for row in pts) + '\nVERTICES 1 201\n200 ' + ' 0' * 200)
  (tmp_path / 'f.vtk').write_bytes(head.format('BINARY', 'float').encode()
                                   + pts.astype('>f4').tobytes() + b'\n')
  for name, atol in (('a.xyz', 1e-12), ('b.csv', 1e-12), ('c.pts', 1e-8), ('d.txt', 0),
                     ('e.vtk', 0), ('f.vtk', 1e-5)):
    np.testing.assert_allclose(io.read_cloud(tmp_path / name), pts, rtol=1e-7, atol=atol,
                               err_msg=name)
  (tmp_path / 'cut.vtk').write_bytes(head.format('BINARY', 'float').encode() + b'\0' * 100)
  (tmp_path / 'words.txt').write_text('poses of the drive\nnone\n')
  (tmp_path / 'short.csv').write_text('x,y,z\n1,2,3\n4,5\n')
  for name, message in (('cut.vtk', 'truncated: 200 points need 2400 bytes'),
                        ('words.txt', 'no line of three or more numbers'),
                        ('short.csv', 'not a table of numbers after line 2')):
    with pytest.raises(io.CloudFileError, match=message):
      io.read_cloud(tmp_path / name)
  # A folder of scans lists the clouds, not its .txt and .csv (indices, poses).
  assert [p.name for p in io.list_clouds(tmp_path)] == ['a.xyz', 'c.pts', 'cut.vtk', 'e.vtk',
                                                         'f.vtk']


@pytest.mark.parametrize('content, fmt, message', [
    (b'', 'auto', 'file is empty'),
    (b'\0' * 10, 'auto', 'not a whole number of float32 values'),
    (np.zeros(7, '<f4').tobytes(), 'auto', 'fit no .bin layout'),
    (np.zeros(8, '<f4').tobytes(), 'xyzn', "6-column float32 rows .format 'xyzn'"),
    (np.zeros(6, '<f4').tobytes(), 'xyzrgb', 'unknown .bin format'),
])
def test_bad_bin_files_are_clear_errors(tmp_path, content, fmt, message):
  path = tmp_path / 'bad.bin'
  path.write_bytes(content)
  with pytest.raises(io.CloudFileError, match=message):
    io.read_cloud(path, fmt)


def _real_layouts():
  """Every .bin layout written from real scans: name -> (bytes, xyz)."""
  kitti = np.fromfile(shared_path('kitti_object_velodyne', '000000.bin'), '<f4').reshape(-1, 4)
  oxford = np.fromfile(shared_path('example', 'oxford_270.bin'), '<f4').reshape(-1, 6)
  out = {}
  for suffix, dtype in (('', '<f4'), ('64', '<f8')):
    out['xyz' + suffix] = kitti[:, :3].astype(dtype)
    out['xyzi' + suffix] = kitti.astype(dtype)
    out['xyzn' + suffix] = oxford.astype(dtype)
  return out


@pytest.mark.real_data
def test_every_bin_layout_is_detected_and_reads_when_named(tmp_path):
  for fmt, rows in _real_layouts().items():
    path = tmp_path / f'{fmt}.bin'
    rows.tofile(path)
    assert io.detect_bin_format(np.fromfile(path, np.uint8), path) == fmt
    for named in ('auto', fmt):
      xyz = io.read_cloud(path, named)
      assert xyz.dtype == (np.float64 if fmt.endswith('64') else np.float32)
      np.testing.assert_array_equal(xyz, rows[:, :3])


@pytest.mark.real_data
def test_bin_layouts_that_used_to_be_guessed_wrong(tmp_path):
  kitti = np.fromfile(shared_path('kitti_object_velodyne', '000000.bin'), '<f4').reshape(-1, 4)
  # Intensity in [0, 255] that is not an integer: still xyzi, not 4/3 as many xyz rows.
  scaled = np.c_[kitti[:, :3], kitti[:, 3] * 255 + 0.37].astype('<f4')
  scaled.tofile(tmp_path / 'scaled.bin')
  np.testing.assert_array_equal(io.read_cloud(tmp_path / 'scaled.bin'), kitti[:, :3])
  # Integer, non-negative coordinates in an N x 3 file (N divisible by 4): xyz, because
  # column 4 of a 4-wide reading is distributed like the coordinates.
  grid = np.round(kitti[:, :3] * 5)
  grid = (grid - grid.min(axis=0))[: len(grid) // 4 * 4].astype('<f4')
  grid.tofile(tmp_path / 'grid.bin')
  assert io.read_cloud(tmp_path / 'grid.bin').shape == grid.shape
  # Float64 rows named as float32 (or the reverse) are refused, not read as garbage.
  kitti[:, :3].astype('<f8').tofile(tmp_path / 'wide.bin')
  with pytest.raises(io.CloudFileError, match=r"read as 'xyz' it holds .*wrong --format"):
    io.read_cloud(tmp_path / 'wide.bin', 'xyz')
  kitti[: len(kitti) // 2 * 2, :3].tofile(tmp_path / 'narrow.bin')
  with pytest.raises(io.CloudFileError, match="read as 'xyz64'"):
    io.read_cloud(tmp_path / 'narrow.bin', 'xyz64')
  # A small crop centred on one of its points holds float32 subtraction residues (1e-7 m):
  # still a cloud (the synthetic cluster crops of Table III have them).
  oxford = np.fromfile(shared_path('example', 'oxford_270.bin'), '<f4').reshape(-1, 6)[:90]
  crop = oxford.copy()
  crop[:, :3] -= crop[0, :3]
  crop[1:20, 0] = 1.2e-7
  crop.tofile(tmp_path / 'crop.bin')
  assert io.read_cloud(tmp_path / 'crop.bin').shape == (90, 3)
  # A named layout keeps the file's NaN rows (missing returns) for clean_cloud to drop;
  # detection, which must tell layouts apart, refuses more than 1 % of them.
  holes = kitti.copy()
  holes[::20, :3] = np.nan
  holes.tofile(tmp_path / 'holes.bin')
  assert np.isnan(io.read_cloud(tmp_path / 'holes.bin', 'xyzi')).any(axis=1).sum() == len(holes[::20])
  with pytest.raises(io.CloudFileError, match='% of the rows are not finite'):
    io.read_cloud(tmp_path / 'holes.bin')
  # Bytes that are no cloud in any layout: every layout tried is named with its reason.
  np.random.default_rng(0).integers(0, 256, 48_000, np.uint8).tofile(tmp_path / 'noise.bin')
  with pytest.raises(io.CloudFileError, match=r'fit no .bin layout \(xyzn: .*xyz64: '):
    io.read_cloud(tmp_path / 'noise.bin')


@pytest.mark.real_data
def test_truncated_real_file_is_reported(tmp_path):
  data = shared_path('example', 'oxford_270.bin').read_bytes()
  (tmp_path / 'cut.bin').write_bytes(data[:-4])
  with pytest.raises(io.CloudFileError, match='truncated'):
    io.read_cloud(tmp_path / 'cut.bin', 'xyzn')


def test_missing_and_unsupported_files(tmp_path):
  with pytest.raises(io.CloudFileError, match='no such file'):
    io.read_cloud(tmp_path / 'nope.bin')
  (tmp_path / 'x.e57').write_bytes(b'1234')
  with pytest.raises(io.CloudFileError, match='unsupported file type'):
    io.read_cloud(tmp_path / 'x.e57')
  for name, content, message in (('junk.las', b'1234', 'not a readable LAS/LAZ file'),
                                 ('empty.laz', b'', 'file is empty')):
    (tmp_path / name).write_bytes(content)
    with pytest.raises(io.CloudFileError, match=message):
      io.read_cloud(tmp_path / name)
  np.save(tmp_path / 'two.npy', np.zeros((5, 2)))
  with pytest.raises(io.CloudFileError, match=r'expected an \[N, >=3\] array'):
    io.read_cloud(tmp_path / 'two.npy')
  (tmp_path / 'empty.ply').write_bytes(b'')
  with pytest.raises(io.CloudFileError, match='empty'):
    io.read_cloud(tmp_path / 'empty.ply')
  (tmp_path / 'dir').mkdir()
  with pytest.raises(io.CloudFileError, match='holds no point clouds'):
    io.list_clouds(tmp_path / 'dir')


def test_nan_points_are_dropped_and_all_nan_or_coincident_refused():
  pts = np.random.default_rng(1).normal(size=(50, 3)).astype(np.float32)
  pts[3] = np.nan
  pts[7, 1] = np.inf
  cleaned = clean.clean_cloud(pts, 'c')
  assert cleaned.shape == (48, 3) and np.isfinite(cleaned).all()
  with pytest.raises(clean.CloudDataError, match='no finite points'):
    clean.clean_cloud(np.full((4, 3), np.nan), 'c')
  with pytest.raises(clean.CloudDataError, match='all 9 points coincide'):
    clean.clean_cloud(np.ones((9, 3)), 'c')
  with pytest.raises(clean.CloudDataError, match=r'shape \[N, 3\]'):
    clean.clean_cloud(np.ones((9, 4)), 'c')


def test_oxford_index_and_listing(tmp_path):
  for i in range(3):
    np.random.default_rng(i).normal(size=(20, 6)).astype(np.float32).tofile(tmp_path / f'{i}.bin')
  (tmp_path / 'train.txt').write_text('0.bin | 1 2 | 1 2\n1.bin | 0 | 0 2\n2.bin |  | 0\n')
  entries = io.read_oxford_index(tmp_path / 'train.txt')
  assert [e.path.name for e in entries] == ['0.bin', '1.bin', '2.bin']
  assert entries[0].positives == (1, 2) and entries[2].positives == () and entries[1].non_negatives == (0, 2)
  assert io.list_clouds(tmp_path) == [e.path for e in entries]
  (tmp_path / 'bad.txt').write_text('0.bin | 1 x | 2\n')
  with pytest.raises(io.CloudFileError, match='indices must be integers'):
    io.read_oxford_index(tmp_path / 'bad.txt')


def test_crop_and_subsample_pad_by_repetition():
  pts = np.array([[1.0, 0, 0], [0, 30, 0], [5, 5, 1], [0, 0, 19.9]], np.float32)
  assert len(datasets.crop(pts, 20.0)) == 3
  rng = np.random.default_rng(0)
  few = np.random.default_rng(2).normal(size=(10, 3)).astype(np.float32)
  out = datasets.subsample(rng, few, 64)
  assert out.shape == (64, 3)
  assert {tuple(r) for r in out} == {tuple(r) for r in few}  # every point, then repeats
  many = datasets.subsample(rng, np.arange(300, dtype=np.float32).reshape(100, 3), 40)
  assert len({tuple(r) for r in many}) == 40


@pytest.mark.real_data
def test_dataset_batches_are_a_function_of_seed_and_step():
  ds = datasets.CloudDataset.from_source(shared_path('kitti_object_velodyne'))
  assert len(ds) == 6
  a = ds.batch(0, 5, 3, 256)
  np.testing.assert_array_equal(a, ds.batch(0, 5, 3, 256))
  assert not np.array_equal(a, ds.batch(0, 6, 3, 256))
  assert not np.array_equal(a, ds.batch(1, 5, 3, 256))
  assert np.linalg.norm(a, axis=-1).max() < 20.0  # cropped
  # A process of a multi-process run builds only its rows, and gets them exactly.
  np.testing.assert_array_equal(ds.batch(0, 5, 3, 256, rows=[1, 2]), a[1:])
  np.testing.assert_array_equal(ds.batch(0, 5, 3, 256, rows=[0]), a[:1])


def test_dataset_refuses_clouds_far_from_their_sensor(tmp_path):
  (np.random.default_rng(0).normal(size=(100, 3)) + 500).astype(np.float32).tofile(tmp_path / 'a.bin')
  ds = datasets.CloudDataset([tmp_path / 'a.bin'], fmt='xyz', min_points=10)
  with pytest.raises(clean.CloudDataError, match='0 points within 20.0 m'):
    ds.cloud(0)


def test_prefetch_preserves_order():
  assert list(datasets.prefetch(lambda s: s * s, range(3, 12), depth=3)) == [s * s for s in range(3, 12)]


def test_ks_statistic_equals_scipys():
  # scipy.stats is the reference; the library avoids importing it.
  rng = np.random.default_rng(0)
  for a, b in [(rng.normal(size=300), rng.normal(size=500)),
               (rng.uniform(0, 255, 400), rng.normal(0, 20, 900)),
               (np.array([1.0, 1.0, 2.0]), np.array([1.0, 3.0]))]:
    assert io.ks_statistic(a, b) == pytest.approx(stats.ks_2samp(a, b).statistic, abs=1e-12)
