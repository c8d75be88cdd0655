#!/usr/bin/env bash
# Sourced by the README's commands: create .venv with the machine's python3 and install the
# project (editable, with its test and bench extras) into it; reinstall when pyproject.toml
# changes. Leaves PY pointing at the venv's python.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"
PY="$VENV/bin/python"
if [ ! -x "$PY" ]; then
    echo "setting up $VENV (first run; a few minutes)" >&2
    python3 -m venv "$VENV"
fi
STAMP="$VENV/.lookahead-installed"
WANT="$(sha256sum "$ROOT/pyproject.toml" | cut -d' ' -f1)"
if [ ! -f "$STAMP" ] || [ "$(cat "$STAMP")" != "$WANT" ]; then
    "$PY" -m pip install --quiet --disable-pip-version-check --upgrade pip >&2
    # setuptools' "Editable installation ... be careful with folders named like your
    # package" is information, not a problem (our packages live under service/ and clients/);
    # only that message is silenced, deprecation warnings still show
    PYTHONWARNINGS="ignore:Editable installation" \
        "$PY" -m pip install --quiet --disable-pip-version-check -e "$ROOT[test,bench]" >&2
    echo "$WANT" > "$STAMP"
fi
export PY ROOT
