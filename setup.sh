#!/usr/bin/env bash
# Set up ssd_jax in ./.venv: the system library Open3D needs, then the package
# with its test extras. Idempotent; safe to rerun.
set -euo pipefail
cd "$(dirname "$0")"

if ! { /sbin/ldconfig -p 2>/dev/null || ldconfig -p 2>/dev/null; } | grep -q 'libusb-1.0.so.0'; then
  echo "setup: installing libusb-1.0-0 (needed by Open3D)"
  sudo_cmd=""
  if [ "$(id -u)" -ne 0 ]; then sudo_cmd="sudo"; fi
  $sudo_cmd apt-get update -qq
  $sudo_cmd apt-get install -y -qq libusb-1.0-0 >/dev/null
fi

python="${PYTHON:-python3}"
if [ ! -x .venv/bin/python ]; then
  "$python" -m venv .venv
fi
# Pinned versions (constraints.txt): a fresh clone gets the libraries the results were
# measured with, so two machines compute the same numbers.
constraints=(-c constraints.txt)
if [ "${SSD_JAX_UNPINNED:-0}" = "1" ]; then constraints=(); fi
# pip's and setuptools' notes go to a log, shown in full if the install fails.
log=.venv/setup.log
echo "setup: installing ssd_jax and its libraries into .venv (about 3 minutes the first time)"
if ! { .venv/bin/python -m pip install -q --upgrade pip &&
       .venv/bin/python -m pip install -q "${constraints[@]}" -e '.[test]'; } >"$log" 2>&1; then
  cat "$log" >&2
  echo "setup: installing the package failed (the log above is in $log)" >&2
  exit 1
fi
