"""The recording file format of `lookahead record` / `lookahead replay`.

A recording is a stream of MessagePack maps written one after the other (read them back
with `msgpack.Unpacker`). Times `t` are seconds on a monotonic clock since the recording
started. Record types (key `type`):

- `header` (first, once): `format` = "lookahead-recording", `version` = 1, `ns` (key
  namespace), `started_unix` (wall clock, s), `config_toml` (the recorder's machine
  configuration, `lookahead.config.config_to_toml`: replay plans with it; record with the
  same configuration as the service), `software` (the versions of Python and of the
  packages that decide the setpoints' last bits, `software_versions`; replay compares
  exactly only under the same ones).
- `sample`: one message received under `NS/**`: `t`, `key`, `kind` ("put" or "delete"),
  `payload` (bin, the message bytes as received).
- `liveliness`: a token under `NS/alive/**` appeared or went: `t`, `key`, `alive` (bool).
- `applied`: the sample index at which the service took in a segment: `t`, `job`, `seq`
  (the segment), `k` (the k0 of the first setpoint batch whose `applied` list names it) and
  `batch_job` (that batch's job; for a segment of a later job taken in while an earlier
  job still ran, `k` counts samples of `batch_job`).

Readers ignore record types and fields they do not know.
"""

from __future__ import annotations

import platform
from collections.abc import Iterator
from dataclasses import dataclass, field
from importlib import metadata
from typing import BinaryIO

import msgpack

FORMAT = "lookahead-recording"
VERSION = 1
#: the distributions whose versions a recording notes (their arithmetic shapes the setpoints)
SOFTWARE = ("lookahead", "numpy", "scipy", "ruckig", "osqp")


def software_versions() -> dict[str, str]:
    """Python's version and those of `SOFTWARE` in this environment ("?" if not installed)."""
    out = {"python": platform.python_version()}
    for dist in SOFTWARE:
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[dist] = "?"
    return out


class RecordingError(ValueError):
    """Not a recording, or an unsupported version."""


class RecordingWriter:
    """Appends records to a binary file, flushing after each one."""

    def __init__(self, fh: BinaryIO, ns: str, config_toml: str, started_unix: float) -> None:
        self._fh = fh
        self.count = 0
        self._write({"type": "header", "format": FORMAT, "version": VERSION, "ns": ns,
                     "started_unix": started_unix, "config_toml": config_toml,
                     "software": software_versions()})

    def _write(self, record: dict) -> None:
        self._fh.write(msgpack.packb(record, use_bin_type=True))
        self._fh.flush()
        self.count += 1

    def sample(self, t: float, key: str, kind: str, payload: bytes) -> None:
        self._write({"type": "sample", "t": t, "key": key, "kind": kind, "payload": payload})

    def liveliness(self, t: float, key: str, alive: bool) -> None:
        self._write({"type": "liveliness", "t": t, "key": key, "alive": alive})

    def applied(self, t: float, job: str, seq: int, k: int, batch_job: str) -> None:
        self._write({"type": "applied", "t": t, "job": job, "seq": seq, "k": k,
                     "batch_job": batch_job})


@dataclass
class Recording:
    """A recording read back: its header and the records after it, in file order."""

    header: dict
    records: list[dict] = field(default_factory=list)

    def samples(self, suffix: str) -> Iterator[dict]:
        """`sample` records (puts) whose key is NS/<suffix>."""
        key = f"{self.header['ns']}/{suffix}"
        return (r for r in self.records
                if r.get("type") == "sample" and r.get("kind") == "put" and r.get("key") == key)


def read_recording(path: str) -> Recording:
    """Read a whole recording file."""
    with open(path, "rb") as fh:
        unpacker = msgpack.Unpacker(fh, raw=False, strict_map_key=False)
        try:
            header = next(unpacker)
        except StopIteration:
            raise RecordingError(f"{path}: empty file") from None
        except Exception as exc:  # msgpack raises several unrelated exception types
            raise RecordingError(f"{path}: not a recording ({exc.__class__.__name__})") \
                from None
        if not isinstance(header, dict) or header.get("format") != FORMAT:
            raise RecordingError(f"{path}: not a {FORMAT} file")
        if header.get("version") != VERSION:
            raise RecordingError(f"{path}: unsupported version {header.get('version')}")
        records = [r for r in unpacker if isinstance(r, dict)]
    return Recording(header, records)
