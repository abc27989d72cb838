#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# Builds the Doxygen API reference of the installed headers (docs/Doxyfile) and fails if any
# public member, namespace or header in it is undocumented, or if Doxygen warns about anything
# else (a broken comment). Part of the test run (scripts/run_tests.sh).
#   scripts/check_docs.sh                     check; the reference goes to a temporary directory
#   ST_DOCS_OUT=build-docs scripts/check_docs.sh   check and keep the HTML in build-docs/html
# Doxygen warns only about the members of documented scopes: a function of an undocumented
# namespace or a macro of a header without a `/// \file` comment passes in silence. So every
# namespace (but detail) and every header must be documented too; that is read from Doxygen's XML.
# The headers are docs/Doxyfile's INPUT, which must list exactly what the install_headers() calls
# of src/spheretouch/{,*/}meson.build install (and the version header's template).
set -euo pipefail
cd "$(dirname "$0")/.."
command -v doxygen >/dev/null ||
  { echo "docs: doxygen not found (Debian package doxygen: apt-get install doxygen, or scripts/setup.sh)" >&2; exit 2; }
command -v python3 >/dev/null || { echo "docs: python3 not found (Debian package python3)" >&2; exit 2; }

# The installed headers, from the meson.build files: the quoted names inside each install_headers(...)
# call, in that file's directory; `version_hpp` is configure_file()'s output from version.hpp.in.
installed=$(for mb in $(git ls-files 'src/spheretouch/meson.build' 'src/spheretouch/*/meson.build'); do
  dir=$(dirname "$mb")
  calls=$(awk '/install_headers\(/ { on = 1 } on { print } on && /\)[[:space:]]*$/ { on = 0 }' "$mb")
  { grep -o "'[^']*\.hpp'" <<<"$calls" || true; } | tr -d "'" | sed "s|^|$dir/|"
  if grep -q '\bversion_hpp\b' <<<"$calls"; then echo "$dir/version.hpp.in"; fi
done | sort)
# docs/Doxyfile's INPUT (one entry per line, continued with backslashes).
inputs=$(awk '/^INPUT[[:space:]]*=/ { on = 1; sub(/^INPUT[[:space:]]*=/, "") }
              on { line = $0; more = sub(/\\[[:space:]]*$/, "", line); n = split(line, w); for (i = 1; i <= n; i++) print w[i]
                   if (!more) on = 0 }' docs/Doxyfile | sort)
if [ "$installed" != "$inputs" ]; then
  echo "docs: docs/Doxyfile's INPUT is not the installed headers (the install_headers() calls of the meson.build files):" >&2
  comm -23 <(echo "$installed") <(echo "$inputs") | sed 's/^/  installed, not in INPUT: /' >&2
  comm -13 <(echo "$installed") <(echo "$inputs") | sed 's/^/  in INPUT, not installed: /' >&2
  exit 1
fi
headers=$(echo "$inputs" | wc -l)

out="${ST_DOCS_OUT:-}"
keep=1
if [ -z "$out" ]; then out=$(mktemp -d); keep=0; trap 'rm -rf "$out"' EXIT; fi
mkdir -p "$out"
out=$(cd "$out" && pwd)
log="$out/warnings.log"
rm -rf "$out/html" "$out/xml" "$log"
# The Doxyfile as written, with the output placed here and the XML the scope check reads.
if ! { cat docs/Doxyfile; printf 'OUTPUT_DIRECTORY = "%s"\nWARN_LOGFILE = "%s"\nGENERATE_XML = YES\n' "$out" "$log"; } |
  doxygen - >"$out/doxygen.out" 2>&1; then
  cat "$out/doxygen.out" >&2
  echo "docs: doxygen failed" >&2
  exit 1
fi

# Doxygen's warnings, paths relative to the repository, each once (a namespace's member is warned
# about on the namespace's page and on the header's).
warnings=$(sed "s|^$PWD/||" "$log" | grep . | sort -t: -k1,1 -k2,2n -u || true)
undocumented=$(grep 'is not documented' <<<"$warnings" || true)
other=$(grep -v 'is not documented' <<<"$warnings" || true)
# Namespaces and headers without a comment (the scopes whose members Doxygen does not check).
scopes=$(python3 - "$out/xml" <<'EOF'
import os, sys, xml.etree.ElementTree as ET
xml = sys.argv[1]
def text(node):
    return "".join(node.itertext()).strip() if node is not None else ""
for c in ET.parse(os.path.join(xml, "index.xml")).getroot().findall("compound"):
    kind, name = c.get("kind"), c.findtext("name")
    if kind not in ("namespace", "file") or name.endswith("::detail") or "::detail::" in name:
        continue
    if name == "std" or name.startswith("std::"):  # named by a base class (std::runtime_error): not ours
        continue
    d = ET.parse(os.path.join(xml, c.get("refid") + ".xml")).getroot().find("compounddef")
    if text(d.find("briefdescription")) or text(d.find("detaileddescription")):
        continue
    loc = d.find("location")
    where = "src/" + loc.get("file") if loc is not None else "?"  # STRIP_FROM_PATH = src
    if kind == "file":
        print(f"{where}: warning: header has no /// \\file comment (its macros go unchecked)")
    else:
        print(f"{where}:{loc.get('line')}: warning: namespace {name} is not documented (its members go unchecked)")
EOF
)
scopes=$(sort -t: -k1,1 -k2,2n -u <<<"$scopes" | grep . || true)

count() { if [ -z "$1" ]; then echo 0; else wc -l <<<"$1"; fi; }
n_members=$(count "$undocumented"); n_scopes=$(count "$scopes"); n_other=$(count "$other")
if ((n_members + n_scopes + n_other)); then
  ((n_members)) && { echo "docs: $n_members undocumented public members in the installed headers:"; sed 's/^/  /' <<<"$undocumented"; }
  ((n_scopes)) && { echo "docs: $n_scopes undocumented namespaces or headers:"; sed 's/^/  /' <<<"$scopes"; }
  ((n_other)) && { echo "docs: $n_other other Doxygen warnings:"; sed 's/^/  /' <<<"$other"; }
  echo "docs: FAILED: add a one-line /// (or ///<) comment to each (docs/Doxyfile says how several names on one line share one)"
  exit 1
fi
where=""
((keep)) && where=" (HTML: $out/html/index.html)"
echo "docs: Doxygen API reference for $headers headers, 0 undocumented public members$where"
