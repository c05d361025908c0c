"""The patterns that read other libraries' wording (ssd_jax/infra/library_text.py), on lines of
the form those libraries print. The end-to-end tests named in the module's docstring make
the libraries print the real text; these pin how each pattern reads it."""

import types

from ssd_jax.infra import library_text


def test_jax_fatal_line_gives_its_status_and_kind():
  line = ('F1203 14:24:37.323625  123 client.cc:77] Terminating process because the JAX '
          'distributed service detected fatal errors. This most likely indicates that another '
          'task died; absl::Status: DEADLINE_EXCEEDED: Barrier timed out.\r\n')
  status = library_text.jax_fatal_status(line)
  assert status == 'DEADLINE_EXCEEDED: Barrier timed out.'
  assert library_text.jax_stop_reason(status) == 'never_joined'
  assert library_text.jax_stop_reason('UNAVAILABLE: task 1 heartbeat timeout') == 'peer_stopped'
  assert library_text.jax_stop_reason('INTERNAL: something else') == 'other'
  assert library_text.jax_fatal_status('I1203 an info line') is None
  assert library_text.jax_fatal_status('F1203 another fatal error') is None


def test_peer_failures_and_orbax_reads_are_told_apart():
  assert library_text.names_a_peer_failure('[Gloo] connection closed by peer')
  assert not library_text.names_a_peer_failure('shapes (2, 3) and (4,) do not match')
  read = types.SimpleNamespace(object=types.SimpleNamespace(__qualname__='_read_array'),
                               exc_value=ValueError('x'))
  other = types.SimpleNamespace(object=types.SimpleNamespace(__qualname__='my_coroutine'),
                                exc_value=ValueError('unrelated'))
  assert library_text.is_failed_array_read(read)
  assert not library_text.is_failed_array_read(other)
  error = ValueError('DATA_LOSS: Error reading "ocdbt". See full TensorStore details\nmore')
  assert library_text.first_line(error) == 'ValueError: DATA_LOSS: Error reading "ocdbt"'
