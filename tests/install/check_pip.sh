#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# `pip install .` as a Python user runs it, offline: a venv with the system's site packages (numpy,
# meson-python, pybind11 from Debian), pip install --no-build-isolation (pyproject.toml: a core-only
# meson build of the package alone), then the installed package imports from the venv, has its
# version and stubs, runs the examples, and mypy --strict accepts them against what was installed.
# usage: check_pip.sh   (from anywhere; CI runs it in the background)
set -euo pipefail
cd "$(dirname "$0")/../.."
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
fail() { echo "check_pip: $*" >&2; exit 1; }

/usr/bin/python3 -m venv --system-site-packages "$scratch/venv" || fail "python3 -m venv failed (apt-get install python3-venv)"
py="$scratch/venv/bin/python"
# No optimisation and four sources to a file here only: CI checks that the install works, not its
# speed (a user's pip install builds optimised, one file per source), and a whole CI run has 30
# minutes on two cores. In a native file: pip 23.0 (Debian's venv) keeps one value per
# --config-settings key.
printf '[built-in options]\noptimization = %s\nunity = %s\n' "'0'" "'on'" >"$scratch/ci.ini"
"$py" -m pip install --no-build-isolation --no-deps --no-index -q \
  --config-settings=setup-args=--native-file="$scratch/ci.ini" . \
  >"$scratch/pip.log" 2>&1 ||
  { tail -40 "$scratch/pip.log"; fail "pip install . failed"; }
# From the venv, not the build tree: run where the source tree is not on the path.
cd "$scratch"
where=$("$py" -c "import spheretouch, sys; print(spheretouch.__file__)")
case "$where" in "$scratch/venv/"*) ;; *) fail "spheretouch imported from $where, not the venv";; esac
version=$("$py" -c "import spheretouch; print(spheretouch.__version__)")
pkg=$(dirname "$where")
for f in py.typed _core.pyi; do [ -f "$pkg/$f" ] || fail "the installed package lacks $f"; done
"$py" "$OLDPWD/python/examples/touch_boxes.py" >"$scratch/ex.log" || { cat "$scratch/ex.log"; fail "examples/touch_boxes.py failed"; }
"$py" "$OLDPWD/python/examples/contact_force.py" >>"$scratch/ex.log" || { cat "$scratch/ex.log"; fail "examples/contact_force.py failed"; }
"$py" -m mypy --strict --no-incremental --cache-dir=/dev/null "$OLDPWD"/python/examples/*.py >"$scratch/mypy.log" 2>&1 ||
  { cat "$scratch/mypy.log"; fail "mypy --strict on the examples, against the installed package, failed"; }
echo "pip install . into a venv: spheretouch $version from $pkg; examples run; mypy --strict: $(tail -1 "$scratch/mypy.log")"
