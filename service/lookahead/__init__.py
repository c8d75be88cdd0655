"""lookahead: jerk-limited look-ahead feedrate planning and interpolation on the Zenoh bus."""

__version__ = "0.1.0"
PROTOCOL_VERSION = 1
