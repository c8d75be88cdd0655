#!/usr/bin/env bash
# The README's main command: set up .venv, then run the demo (planner service, simulated
# winder and segment publisher on the embedded default: zenoh peers on 127.0.0.1).
# Extra arguments go to `lookahead demo` (e.g. --fast).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/_venv.sh"
cd "$ROOT"
exec "$VENV/bin/lookahead" demo "$@"
