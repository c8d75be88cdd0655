#!/usr/bin/env bash
# Re-record tests/data/golden-short.rec: a --fast heuristic service planning the first 350
# points of tube-1450 in 60-point segments (job "golden"), recorded on a private loopback
# port. Re-record whenever the setpoints change (even by rounding) or the software
# versions move on: replay is bit-identical only under the recording's versions.
# Usage: tests/data/record_golden.sh [python]   (default: .venv/bin/python)
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
PY="${1:-$ROOT/.venv/bin/python}"
TMP="$(mktemp -d)"
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$TMP"' EXIT
# the service listens there; the clients find it and each other (lookahead.bus)
LOOKAHEAD_ZENOH_LISTEN="$("$PY" -c 'from lookahead.bus import free_tcp_endpoint
print(free_tcp_endpoint())')"
export LOOKAHEAD_ZENOH_LISTEN
unset LOOKAHEAD_ZENOH_CONNECT LOOKAHEAD_MACHINE_ID
"$PY" - "$TMP/golden.csv" <<'PYEOF'
import sys

import numpy as np

from lookahead.geometry import preset_points

axes, points, _ = preset_points("tube-1450")
np.savetxt(sys.argv[1], points[:350], delimiter=",", header=",".join(axes), comments="")
PYEOF
"$PY" -m lookahead serve --fast --method heuristic --log-level WARNING &
"$PY" -m lookahead record --jobs 1 "$TMP/golden.rec" &
RECORDER=$!
sleep 2  # the recorder must be subscribed before the first segment goes out
"$PY" -m lookahead publish "$TMP/golden.csv" --job golden --chunk 60 --quiet
wait "$RECORDER"
"$PY" -m lookahead replay "$TMP/golden.rec"  # must be bit-identical, else keep the old one
cp "$TMP/golden.rec" "$ROOT/tests/data/golden-short.rec"
