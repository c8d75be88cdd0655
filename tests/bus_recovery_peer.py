"""A subscriber process for tests/test_bus_recovery.py (run as a script, so the test can
pause it with SIGSTOP): connects to argv[1], takes key argv[2] through
`lookahead.bus.recovering_subscriber`, prints "ready", then prints the integers it received
(8-byte little-endian heads of the payloads) as one JSON line once it has argv[3] of them
or nothing arrived for argv[4] s."""

from __future__ import annotations

import json
import struct
import sys
import time

import zenoh

from lookahead.bus import recovering_subscriber, zenoh_config
from lookahead.config import ZenohSection


def main() -> None:
    endpoint, key_expr, want, idle_s = sys.argv[1], sys.argv[2], int(sys.argv[3]), float(
        sys.argv[4])
    session = zenoh.open(zenoh_config(ZenohSection(listen=(), connect=(endpoint,))))
    lost: list[int] = []
    sub = recovering_subscriber(session, key_expr, 8192, on_miss=lost.append)
    print("ready", flush=True)
    got: list[int] = []
    last = time.monotonic()
    while len(got) < want and time.monotonic() - last < idle_s:
        sample = sub.try_recv()
        if sample is None:
            time.sleep(0.002)
            continue
        got.append(struct.unpack("<q", sample.payload.to_bytes()[:8])[0])
        last = time.monotonic()
    print(json.dumps({"got": got, "lost": lost}), flush=True)
    session.close()


if __name__ == "__main__":
    main()
