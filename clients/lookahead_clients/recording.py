"""The recording file format of `lookahead record` / `lookahead replay`.

A recording is a stream of MessagePack maps written one after the other (read them back
with `msgpack.Unpacker`). Times `t` are seconds on a monotonic clock since the recording
started. Record types (key `type`):

- `header` (first, once): `format` = "lookahead-recording", `version` = 1, `ns` (key
  namespace), `started_unix` (wall clock, s), `config_toml` (the recorder's machine
  configuration, `lookahead.config.config_to_toml`: replay plans with it; record with the
  same configuration as the service), `software` (the versions of Python and of the
  packages that decide the setpoints' last bits, `software_versions`) and `fp_env` (what
  picks the floating-point kernels those packages run: CPU, SIMD features, BLAS build and
  threads, `floating_point_environment`). Replay compares bit for bit only where both
  match, since the same versions on another CPU round differently in the last bits.
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

import os
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


#: CPU flags that select SIMD kernels in numpy, OpenBLAS and HiGHS (x86 and Arm names)
SIMD_FLAGS = ("sse4_1", "sse4_2", "avx", "avx2", "fma", "avx512f", "avx512dq", "avx512bw",
              "avx512vl", "avx512_bf16", "avx512_fp16", "amx_tile", "asimd", "sve", "sve2")
#: environment variables that change which BLAS kernel runs, or how many threads split it
FP_ENV_VARS = ("OPENBLAS_CORETYPE", "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS",
               "MKL_NUM_THREADS", "NPY_DISABLE_CPU_FEATURES")


#: /proc/cpuinfo fields that name the CPU (vendor, model name, family/model/stepping)
CPU_ID_FIELDS = ("vendor_id", "model name", "cpu family", "model", "stepping", "cpu model",
                 "cpu implementer", "cpu part")


def _cpu_info() -> tuple[str, list[str]]:
    """The CPU's identity ("vendor / model name / family-model-stepping") and its SIMD flags
    of `SIMD_FLAGS`, from the first processor of /proc/cpuinfo (Linux; elsewhere
    `platform.processor()` and no flags)."""
    ident: dict[str, str] = {}
    flags: set[str] = set()
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                if not line.strip():
                    break  # the first processor's block is enough
                name, _, value = line.partition(":")
                name = name.strip().lower()
                if name in CPU_ID_FIELDS:
                    ident.setdefault(name, value.strip())
                elif name in ("flags", "features"):
                    flags = set(value.split())
    except OSError:
        pass
    model = " / ".join(ident[k] for k in CPU_ID_FIELDS if k in ident)
    return model or platform.processor() or "?", [f for f in SIMD_FLAGS if f in flags]


def _blas_config(module_name: str) -> str:
    """The BLAS a package was built with (name, version, configuration string), or '?'."""
    try:
        module = __import__(module_name)
        blas = module.show_config(mode="dicts")["Build Dependencies"]["blas"]
    except Exception:  # show_config's layout differs between releases; then we cannot say
        return "?"
    return " ".join(str(blas.get(k, "")) for k in ("name", "version", "openblas configuration")
                    ).strip()


def floating_point_environment() -> dict:
    """What decides the last bits of the same code's floats on this machine: the CPU (model,
    SIMD flags), numpy's enabled SIMD dispatch targets, the BLAS of numpy and scipy, the
    usable CPU count (OpenBLAS splits reductions by thread count) and `FP_ENV_VARS`."""
    model, simd = _cpu_info()
    try:
        from numpy._core._multiarray_umath import __cpu_features__ as features
        numpy_simd = sorted(k for k, on in features.items() if on)
    except ImportError:  # numpy < 2 keeps it elsewhere; the CPU flags still tell
        numpy_simd = []
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:
        cpus = os.cpu_count() or 0
    return {"machine": platform.machine(), "cpu_model": model, "cpu_simd": simd,
            "numpy_simd": numpy_simd, "numpy_blas": _blas_config("numpy"),
            "scipy_blas": _blas_config("scipy"), "cpus": cpus,
            "env": {k: os.environ[k] for k in FP_ENV_VARS if k in os.environ}}


class RecordingError(ValueError):
    """Not a recording, or an unsupported version."""


class RecordingWriter:
    """Appends records to a binary file, flushing after each one."""

    def __init__(self, fh: BinaryIO, ns: str, config_toml: str, started_unix: float) -> None:
        self._fh = fh
        self.count = 0
        self._write({"type": "header", "format": FORMAT, "version": VERSION, "ns": ns,
                     "started_unix": started_unix, "config_toml": config_toml,
                     "software": software_versions(),
                     "fp_env": floating_point_environment()})

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
