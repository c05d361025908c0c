"""ssd_jax.infra.cli: one-line errors for command-line mistakes, and the project's configs and
console scripts from any working directory."""

import os
import subprocess
import sys

import pytest

from ssd_jax.infra import cli
from tests.conftest import shared_path

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BIN = os.path.dirname(sys.executable)


def test_config_paths_resolve_to_the_project_from_anywhere(tmp_path, monkeypatch):
  monkeypatch.chdir(tmp_path)
  packaged = os.path.join(ROOT, 'configs', 'training', 'paper_small.py')
  assert os.path.samefile(cli.resolve_config_path('configs/training/paper_small.py'), packaged)
  # A config in a folder of configs/, with an argument.
  resolved, arg = cli.resolve_config_path('configs/experiments/feat3dnet_small.py:pretrain'
                                          ).rsplit(':', 1)
  assert arg == 'pretrain' and os.path.samefile(
      resolved, os.path.join(ROOT, 'configs', 'experiments', 'feat3dnet_small.py'))
  # A file of the user's own wins; names the project lacks stay as given (and fail later).
  (tmp_path / 'configs' / 'training').mkdir(parents=True)
  (tmp_path / 'configs' / 'training' / 'paper_small.py').write_text('')
  mine = 'configs/training/paper_small.py'
  assert cli.resolve_config_path(mine) == mine
  assert cli.resolve_config_path('configs/no_such.py') == 'configs/no_such.py'
  assert cli.resolve_config_path('my/cfg.py') == 'my/cfg.py'
  args = ['prog', '--config', 'configs/training/ours.py', '--config.seed=1', '--workdir=w']
  monkeypatch.setattr(cli, '_CONFIG_FLAGS', {'config'})
  out = cli._resolve_config_args(args)   # pylint: disable=protected-access
  assert os.path.samefile(out[2], os.path.join(ROOT, 'configs', 'training', 'ours.py'))
  assert out[:2] + out[3:] == args[:2] + args[3:]


@pytest.mark.real_data
@pytest.mark.multiprocess
@pytest.mark.slow
def test_console_scripts_register_and_train_outside_the_repository(tmp_path):
  """`ssd-jax-register` with the shipped model and `ssd-jax-train` with a project config
  run from a folder that is not the repository."""
  cloud = shared_path('kitti_object_velodyne', '000000.bin')
  out = subprocess.run([os.path.join(BIN, 'ssd-jax-register'), f'--cloud1={cloud}',
                        f'--cloud2={cloud}', '--descriptor=learned'],
                       cwd=tmp_path, capture_output=True, text=True, timeout=300)
  assert out.returncode == 0, out.stderr[-3000:]
  assert 'T_12 =' in out.stdout and 'learned descriptors' in out.stdout
  out = subprocess.run(
      [os.path.join(BIN, 'ssd-jax-train'), '--config=configs/training/paper_small.py',
       f'--workdir={tmp_path / "run"}', f'--config.data.path={cloud.parent}', '--config.data.eval_path=',
       '--config.data.num_points=512', '--config.model.num_clusters=32',
       '--config.model.num_samples=16', '--config.train.num_steps=2',
       '--config.progress_bar=False'],
      cwd=tmp_path, capture_output=True, text=True, timeout=300)
  assert out.returncode == 0, out.stderr[-3000:]
  assert (tmp_path / 'run' / 'checkpoints' / '2').is_dir()


@pytest.mark.multiprocess
def test_cli_reports_bad_config_without_traceback(tmp_path):
  out = subprocess.run(
      [sys.executable, '-m', 'experiments.train', '--config=configs/training/paper_small.py',
       f'--workdir={tmp_path}', '--config.model.descriptor_dim=20',
       f'--config.data.path={tmp_path}'],
      cwd=ROOT, capture_output=True, text=True, timeout=300)
  assert out.returncode != 0
  assert 'error: model.descriptor_dim must be one of (16, 32, 64, 128), got 20' in out.stderr
  assert 'Traceback' not in out.stderr


@pytest.mark.multiprocess
def test_cli_mistakes_end_in_one_line(tmp_path):
  (tmp_path / 'a_file').write_text('')
  data = f'--config.data.path={tmp_path}'
  cases = [
      (['--config=configs/training/paper_small.py', '--config.train.some_key=3'],
       "the config has no field \"'some_key'\""),
      (['--config=configs/training/paper_small.py', '--config.train.num_steps=abc'],
       "flag --config.train.num_steps=abc: invalid literal for int()"),
      (['--config=configs/no_such.py'], "error: configs/no_such.py [Errno 2] No such file"),
      (['--config=configs/training/paper_small.py', f'--workdir={tmp_path / "a_file"}', data],
       'cannot create it as a folder (File exists)'),
  ]
  for args, message in cases:
    if not any(a.startswith('--workdir') for a in args):
      args = args + [f'--workdir={tmp_path / "w"}']
    out = subprocess.run([sys.executable, '-m', 'experiments.train', *args], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode != 0 and message in out.stderr, (args, out.stderr[-2000:])
    assert 'Traceback' not in out.stderr


_FAST_EXIT_SCRIPT = """
import atexit, ctypes, sys, threading, time
from ssd_jax.infra import cli
def late_write():
  time.sleep(0.3)
  open(sys.argv[1] + '.thread', 'w').write('thread done')
def main(argv):
  atexit.register(lambda: open(sys.argv[1], 'w').write('hook ran'))
  if 'thread' in argv[1:]:
    threading.Thread(target=late_write).start()
  ctypes.CDLL(None).printf(b'from C, buffered\\n')
  print('from Python')
  if 'fail' in argv[1:]:
    raise SystemExit('error: asked to fail')
cli.run(main, fast_exit=True)
"""


@pytest.mark.multiprocess
def test_fast_exit_keeps_atexit_hooks_and_buffered_output(tmp_path):
  """`cli.run(fast_exit=True)` skips the interpreter's teardown but still runs the
  atexit hooks and flushes C's stdout buffer (a pipe here, so fully buffered); a failing
  command, or one that leaves a non-daemon thread running, exits the usual way."""
  script = tmp_path / 'fast_exit_command.py'
  script.write_text(_FAST_EXIT_SCRIPT)
  out = subprocess.run([sys.executable, str(script), str(tmp_path / 'hook')], cwd=ROOT,
                       capture_output=True, text=True, timeout=120)
  assert out.returncode == 0, out.stderr[-2000:]
  assert 'from C, buffered' in out.stdout and 'from Python' in out.stdout
  assert (tmp_path / 'hook').read_text() == 'hook ran'
  out = subprocess.run([sys.executable, str(script), str(tmp_path / 'hook2'), 'fail'],
                       cwd=ROOT, capture_output=True, text=True, timeout=120)
  assert out.returncode == 1 and out.stderr.strip().endswith('error: asked to fail')
  assert (tmp_path / 'hook2').read_text() == 'hook ran'
  out = subprocess.run([sys.executable, str(script), str(tmp_path / 'hook3'), 'thread'],
                       cwd=ROOT, capture_output=True, text=True, timeout=120)
  assert out.returncode == 0 and (tmp_path / 'hook3.thread').read_text() == 'thread done'
