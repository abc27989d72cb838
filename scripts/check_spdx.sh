#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# Every source file of the project carries an SPDX license line in its first three lines
# (LICENSE: BSD-3-Clause). Part of the test run (scripts/run_tests.sh).
#   scripts/check_spdx.sh           list the tracked source files without one; fail if any
# Source files: code, build files, scripts, scene and unit files. Data (meshes, pose files, fuzz
# corpora and dictionaries, recorded results) and documentation are not source.
set -euo pipefail
cd "$(dirname "$0")/.."
mapfile -t files < <(git ls-files '*.cpp' '*.hpp' '*.inl' '*.in' '*.py' '*.sh' '*.gp' '*.js' '*.html' '*.target' \
  'meson.build' '*/meson.build' 'meson_options.txt' '.ci/run' 'configs/*.toml' 'perf/*.toml' 'pyproject.toml' \
  'CMakeLists.txt' '*.cmake' '*.pyi' 'docs/Doxyfile')
bad=()
for f in "${files[@]}"; do
  [ -f "$f" ] || continue  # deleted in the work tree, not yet in the index
  head -n 3 "$f" | grep -q 'SPDX-License-Identifier: BSD-3-Clause' || bad+=("$f")
done
if ((${#bad[@]})); then
  printf 'spdx: %d source files lack "SPDX-License-Identifier: BSD-3-Clause" in their first 3 lines:\n' "${#bad[@]}" >&2
  printf '  %s\n' "${bad[@]}" >&2
  exit 1
fi
echo "spdx: ${#files[@]} source files carry the BSD-3-Clause SPDX line"
