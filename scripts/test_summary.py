#!/usr/bin/env python3
# SPDX-License-Identifier: BSD-3-Clause
"""Prints, for each meson build directory given, one line per test (result, duration, its
'test cases' line) and, for every test that did not pass, the lines of its log that say why
(doctest ERROR/FATAL blocks, sanitizer reports, the last lines before it ended). CI shows only
the end of its output: this puts what failed there.

usage: test_summary.py BUILD_DIR..."""
import json
import re
import sys

COUNT = re.compile(r'^\[(doctest|python|install)\] test cases:.*$', re.M)
WHY = re.compile(r'ERROR|FATAL|crashed|[Ss]anitizer|SUMMARY|Assertion|terminate|check_install:|Traceback|Error')


def why_lines(text, limit=40):
    lines = text.splitlines()
    picked = []
    for i, line in enumerate(lines):
        if WHY.search(line):
            picked.extend(lines[i:i + 4])  # the check and its expanded values
        if len(picked) >= limit:
            break
    tail = lines[-15:]
    return picked[:limit], tail


def main(dirs):
    for d in dirs:
        try:
            with open(f'{d}/meson-logs/testlog.json') as f:
                tests = [json.loads(line) for line in f if line.strip()]
        except OSError as e:
            print(f'{d}: no test log ({e.strerror})')
            continue
        for t in tests:
            out = (t.get('stdout') or '') + (t.get('stderr') or '')
            m = COUNT.search(out)
            if m:
                line = m.group(0)
            elif t['result'] == 'OK':
                line = '(prints no test-case count)'
            else:
                line = '(no test-case count: it ended before its summary)'
            print(f"{d}: {t['name']:<40} {t['result']:<8} {t['duration']:7.1f} s  {line}")
            if t['result'] not in ('OK', 'EXPECTEDFAIL', 'SKIP'):
                picked, tail = why_lines(out)
                for p in picked:
                    print(f'    | {p[:300]}')
                print('    | ... last lines:')
                for p in tail:
                    print(f'    | {p[:300]}')


if __name__ == '__main__':
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(sys.argv[1:])
