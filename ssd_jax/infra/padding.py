"""Static shapes for jitted code: arrays are padded to a few sizes and masked, so that
`jax.jit` compiles one program per size bucket, not one per input length."""


def bucket(n: int, smallest: int) -> int:
  """The power of two >= n (n >= 0), at least `smallest`: the padded length of n rows."""
  return max(smallest, 1 << (max(n, 1) - 1).bit_length())
