"""The streaming core of the service: job assembly, the deterministic engine, pacing.

Nothing here imports zenoh or reads the wall clock (the pacer takes times as arguments);
`lookahead.service` wraps it on the bus.
"""
