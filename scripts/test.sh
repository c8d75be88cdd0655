#!/usr/bin/env bash
# The README's test command: set up .venv, lint, run the test suite (slow benchmarks are
# skipped unless LOOKAHEAD_SLOW=1). Extra arguments go to pytest.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/_venv.sh"
cd "$ROOT"
"$PY" -m ruff check service clients tests bench
set +e
"$PY" -m pytest "$@"
rc=$?
set -e
if [ "$rc" -eq 5 ]; then
    echo "error: pytest collected no tests" >&2
    exit 1
fi
exit "$rc"
