#!/usr/bin/env bash
# The README's test command: set up .venv, lint, run the test suite (slow benchmarks are
# skipped unless LOOKAHEAD_SLOW=1) on one pytest-xdist worker per core, at most 4
# (LOOKAHEAD_TEST_WORKERS overrides: 0 runs in this process). Extra arguments go to pytest.
#
# Why workers: on a 2-core machine of CI's kind the suite took 810 s in one process, 452 s on
# two (stop 50, same tests, all passed both ways); the tests that judge real-time streams
# (underruns, take-overs) passed with the other core busy. Every bus test listens on its own
# random loopback port with multicast scouting off, so workers never see each other.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/_venv.sh"
cd "$ROOT"
"$PY" -m ruff check service clients tests bench
set +e
"$PY" -m pytest --numprocesses "${LOOKAHEAD_TEST_WORKERS:-auto}" --maxprocesses 4 "$@"
rc=$?
set -e
if [ "$rc" -eq 5 ]; then
    echo "error: pytest collected no tests" >&2
    exit 1
fi
exit "$rc"
