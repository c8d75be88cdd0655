"""Machine configuration: a TOML file loaded into a typed, immutable `Config`.

Every key has a default that runs the demo (a two-drive filament winder, DESIGN.md
"Machine configuration"). Errors name the file, the key and what is wrong; all errors of a
file are collected and raised together as one `ConfigError`.

Environment overrides (applied after the file): LOOKAHEAD_<SECTION>_<KEY>, e.g.
LOOKAHEAD_ZENOH_CONNECT="tcp/router:7447" (lists are comma-separated),
LOOKAHEAD_MACHINE_ID="winder-2", LOOKAHEAD_PLANNER_METHOD="heuristic".
"""

from __future__ import annotations

import math
import os
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from lookahead.limits import AxisLimits
from lookahead.protocol import JOB_ID_RE

PLANNER_METHODS = ("heuristic", "lp")
ZENOH_MODES = ("peer", "client", "router")
GCODE_DIALECTS = ("marlin", "rs274")
GCODE_AXIS_LETTERS = "XYZUVWABC"
FITS = ("cubic", "pchip", "linear", "smooth")
_ENDPOINT_RE = re.compile(
    r"^(?P<proto>tcp|udp|tls|quic|ws|unixsock-stream|serial)/(?P<addr>[^#?]+)(?:[#?].*)?$"
)
_HOSTPORT_RE = re.compile(r"^(?P<host>\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]+):(?P<port>\d{1,5})$")


class ConfigError(ValueError):
    """One or more configuration errors, each 'FILE: section.key: what is wrong'."""

    def __init__(self, errors: list[str]) -> None:
        super().__init__("\n".join(errors))
        self.errors = errors


@dataclass(frozen=True)
class MachineSection:
    """The machine: its axes, units, limits (unit/s, unit/s^2, unit/s^3), metric, sample time."""

    id: str = "winder"
    axes: tuple[str, ...] = ("X", "C")
    units: tuple[str, ...] = ("mm", "deg")
    vmax: tuple[float, ...] = (500.0, 720.0)
    amax: tuple[float, ...] = (2000.0, 3000.0)
    jmax: tuple[float, ...] = (20000.0, 30000.0)
    #: C scaled by pi/180 * R (R = 100 mm) so that the feed is the fibre speed in mm/s
    path_scale: tuple[float, ...] = (1.0, math.pi / 180.0 * 100.0)
    dt: float = 0.001

    @property
    def limits(self) -> AxisLimits:
        return AxisLimits(np.array(self.vmax), np.array(self.amax), np.array(self.jmax))

    @property
    def naxes(self) -> int:
        return len(self.axes)


@dataclass(frozen=True)
class PlannerSection:
    """Planning: method, look-ahead window, fit of point streams, safety margin on limits."""

    #: "heuristic" by default: on the fast corpus through the service's engine it made 0
    #: fallbacks with a replan p99 of at most 184 ms, where the windowed LP made 1 fallback
    #: and replans of up to 4.8 s (bench/results/corpus.json), longer than the service's
    #: buffer; the LP winds 0-5 % faster where it works ("lp")
    method: str = "heuristic"
    #: look-ahead window length in seconds of motion at full feed (>= 3 braking distances)
    horizon_s: float = 2.0
    #: fraction of each limit the planner plans to (the checker judges against 1.0)
    margin: float = 0.98
    #: default fit of `points` segments when a job's segment 0 names none
    fit: str = "cubic"
    #: how far fits `linear` (corner blends) and `smooth` may leave the points' polyline,
    #: path units, where a segment gives no `tolerance` (0: exact stop at every corner)
    tolerance: float = 0.05


@dataclass(frozen=True)
class ServiceSection:
    """The service loop: batching, pacing, status rate, gap timeout."""

    batch: int = 10  # samples per setpoint batch
    lead_s: float = 0.05  # real-time mode: publish this far ahead of due time
    status_hz: float = 10.0
    gap_timeout_s: float = 5.0  # how long a missing seq is waited for
    #: caps on what the service holds received but not executed (points and control
    #: points; estimated bytes: arrays plus the measured per-point and per-segment cost of
    #: the fits, stream/assembler.py): `accepting` turns false at either. They trade memory
    #: for how far ahead a publisher may send without pacing: a 568 x 200-point CAM program
    #: (~240 MB by the estimate, an upper bound) fits in one burst.
    max_buffered_points: int = 250_000
    max_buffered_bytes: int = 512 * 1024 * 1024


@dataclass(frozen=True)
class GcodeSection:
    """G-code input: which letter drives which machine axis, letters to drop, dialect."""

    #: "LETTER:AXIS" pairs; letters X Y Z U V W are linear (G20 converts them), A B C rotary.
    #: Empty (the default) means `auto_letters` of the machine's axes: X -> X, A -> C on the
    #: two-drive winder.
    letters: tuple[str, ...] = ()
    #: letters a program may use that this machine drops (with a warning), e.g. ["B"]
    ignore: tuple[str, ...] = ()
    #: "marlin" (fiberpath's target: G0 takes the modal F like G1) or "rs274" (LinuxCNC:
    #: G0 is a rapid that ignores F; F applies to the linear axes when any of them moves)
    dialect: str = "marlin"

    @property
    def letter_map(self) -> dict[str, str]:
        """{letter: machine axis} of `letters` (upper-case letters)."""
        return {pair.split(":", 1)[0].strip().upper(): pair.split(":", 1)[1].strip()
                for pair in self.letters}


@dataclass(frozen=True)
class ZenohSection:
    """Zenoh session: mode and endpoints (locators such as tcp/127.0.0.1:7447)."""

    mode: str = "peer"
    listen: tuple[str, ...] = ("tcp/127.0.0.1:7447",)
    connect: tuple[str, ...] = ()
    #: optional zenoh JSON5 config file (TLS, user/password, access control)
    config_file: str = ""
    multicast_scouting: bool = False


@dataclass(frozen=True)
class Config:
    machine: MachineSection = MachineSection()
    planner: PlannerSection = PlannerSection()
    service: ServiceSection = ServiceSection()
    gcode: GcodeSection = GcodeSection()
    zenoh: ZenohSection = ZenohSection()

    @property
    def ns(self) -> str:
        """Key namespace, lookahead/<machine-id>."""
        return f"lookahead/{self.machine.id}"

    @property
    def gcode_letters(self) -> dict[str, str]:
        """G-code letter -> machine axis: `gcode.letters`, or `auto_letters` of the machine's
        axes where it is empty."""
        if self.gcode.letters:
            return self.gcode.letter_map
        return GcodeSection(letters=auto_letters(self.machine.axes)).letter_map

    def gcode_options(self, ignore: str | tuple[str, ...] = (), dialect: str | None = None
                      ) -> dict[str, Any]:
        """Keyword arguments of `lookahead.geometry.gcode.read_gcode` for this machine:
        its letters, axes, path metric, `gcode.ignore` plus `ignore` (letters, e.g. "B" or
        "B,Y"), and `dialect` (default `gcode.dialect`)."""
        extra = tuple(ignore.replace(",", " ").split()) if isinstance(ignore, str) else ignore
        return {"axis_map": self.gcode_letters, "axes": list(self.machine.axes),
                "ignore": tuple(x.upper() for x in (*self.gcode.ignore, *extra)),
                "dialect": dialect or self.gcode.dialect,
                "path_scale": list(self.machine.path_scale)}


_SECTIONS: dict[str, type] = {
    "machine": MachineSection,
    "planner": PlannerSection,
    "service": ServiceSection,
    "gcode": GcodeSection,
    "zenoh": ZenohSection,
}


def machine_names() -> list[str]:
    """The shipped machine configurations (package `lookahead.machines`)."""
    from importlib import resources

    return sorted(p.name[:-5] for p in resources.files("lookahead.machines").iterdir()
                  if p.name.endswith(".toml"))


def shipped_machine(name: str) -> str | None:
    """The file of shipped machine `name` if `name` is one and no file of that name exists
    here, else None."""
    from importlib import resources

    if Path(name).exists() or name not in machine_names():
        return None
    return str(resources.files("lookahead.machines") / f"{name}.toml")


def default_config() -> Config:
    return Config()


def load_config(path: str | os.PathLike[str] | None = None,
                environ: Mapping[str, str] | None = None) -> Config:
    """Load a TOML file (None: defaults only), then environment overrides; validate. `path`
    may also name a shipped machine (`machine_names`, e.g. "winder3")."""
    if path is not None:
        path = shipped_machine(str(path)) or path
    source = str(path) if path is not None else "<defaults>"
    raw: dict[str, Any] = {}
    if path is not None:
        try:
            text = Path(path).read_text(encoding="utf-8")
        except OSError as exc:
            raise ConfigError([f"{source}: cannot read: {exc.strerror or exc}"]) from None
        try:
            raw = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError([f"{source}: not valid TOML: {exc}"]) from None
    env = os.environ if environ is None else environ
    return build_config(raw, source, env)


def build_config(raw: Mapping[str, Any], source: str = "<config>",
                 environ: Mapping[str, str] | None = None) -> Config:
    """Validate a parsed TOML mapping (+ env overrides) into a `Config`."""
    errors: list[str] = []
    raw = {k: dict(v) if isinstance(v, Mapping) else v for k, v in raw.items()}
    for name in raw:
        if name not in _SECTIONS:
            errors.append(f"{source}: {name}: unknown section (known: {', '.join(_SECTIONS)})")
        elif not isinstance(raw[name], dict):
            errors.append(f"{source}: {name}: must be a table")
    _apply_env(raw, environ or {}, errors)
    values: dict[str, Any] = {}
    for name, cls in _SECTIONS.items():
        table = raw.get(name, {})
        if not isinstance(table, dict):
            table = {}
        values[name] = _build_section(name, cls, table, source, errors)
    if not errors:
        _check_cross(values, source, errors)
    if errors:
        raise ConfigError(errors)
    return Config(**values)


def _apply_env(raw: dict[str, Any], environ: Mapping[str, str], errors: list[str]) -> None:
    for var, text in environ.items():
        if not var.startswith("LOOKAHEAD_"):
            continue
        rest = var[len("LOOKAHEAD_"):].lower()
        section = next((s for s in _SECTIONS if rest.startswith(s + "_")), None)
        if section is None:
            continue
        key_name = rest[len(section) + 1:]
        defaults = _SECTIONS[section]()
        if not hasattr(defaults, key_name):
            errors.append(f"${var}: {section}.{key_name}: unknown key")
            continue
        default = getattr(defaults, key_name)
        value: Any
        if isinstance(default, tuple):
            value = [_env_scalar(p.strip(), default[0] if default else "")
                     for p in text.split(",") if p.strip()]
        else:
            value = _env_scalar(text, default)
        table = raw.setdefault(section, {})
        if isinstance(table, dict):
            table[key_name] = value


def _env_scalar(text: str, like: Any) -> Any:
    if isinstance(like, bool):
        return text.strip().lower() in ("1", "true", "yes", "on")
    if isinstance(like, int | float):
        try:
            return float(text) if isinstance(like, float) else int(text)
        except ValueError:
            return text  # reported by validation with the key's name
    return text


def _build_section(name: str, cls: type, table: dict[str, Any], source: str,
                   errors: list[str]) -> Any:
    defaults = cls()
    known = {f.name for f in fields(cls)}
    out: dict[str, Any] = {}
    for key_name, value in table.items():
        where = f"{source}: {name}.{key_name}"
        if key_name not in known:
            errors.append(f"{where}: unknown key (known: {', '.join(sorted(known))})")
            continue
        default = getattr(defaults, key_name)
        try:
            out[key_name] = _coerce(value, default)
        except ValueError as exc:
            errors.append(f"{where}: {exc}")
    try:
        section = cls(**out)
    except TypeError as exc:  # pragma: no cover - keys are filtered above
        errors.append(f"{source}: {name}: {exc}")
        return defaults
    _check_section(name, section, source, errors)
    return section


def _coerce(value: Any, default: Any) -> Any:
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ValueError(f"expected true or false, got {value!r}")
        return value
    if isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"expected an integer, got {value!r}")
        return value
    if isinstance(default, float):
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"expected a number, got {value!r}")
        return float(value)
    if isinstance(default, str):
        if not isinstance(value, str):
            raise ValueError(f"expected a string, got {value!r}")
        return value
    if isinstance(default, tuple):
        if not isinstance(value, list):
            raise ValueError(f"expected an array, got {value!r}")
        like = default[0] if default else ""
        return tuple(_coerce(v, like) for v in value)
    raise ValueError(f"unsupported value {value!r}")  # pragma: no cover


def _positive_finite(values: tuple[float, ...] | float) -> bool:
    vals = values if isinstance(values, tuple) else (values,)
    return all(math.isfinite(v) and v > 0 for v in vals)


def _check_section(name: str, sec: Any, source: str, errors: list[str]) -> None:
    def err(key_name: str, what: str) -> None:
        errors.append(f"{source}: {name}.{key_name}: {what}")

    if name == "machine":
        if not JOB_ID_RE.match(sec.id):
            err("id", f"must be 1..64 characters of A-Za-z0-9_.-, got {sec.id!r}")
        if not sec.axes:
            err("axes", "at least one axis is needed")
        if len(set(sec.axes)) != len(sec.axes) or any(not a for a in sec.axes):
            err("axes", f"axis names must be distinct and non-empty, got {list(sec.axes)}")
        n = len(sec.axes)
        for key_name in ("units", "vmax", "amax", "jmax", "path_scale"):
            val = getattr(sec, key_name)
            if len(val) != n:
                err(key_name, f"needs one entry per axis ({n}: {', '.join(sec.axes)}), "
                    f"got {len(val)}")
            elif key_name != "units" and not _positive_finite(val):
                err(key_name, f"every entry must be finite and > 0, got {list(val)}")
        if not _positive_finite(sec.dt) or sec.dt > 0.1:
            err("dt", f"must be finite, > 0 and <= 0.1 s, got {sec.dt}")
    elif name == "planner":
        if sec.method not in PLANNER_METHODS:
            err("method", f"unknown planner method {sec.method!r} "
                f"(known: {', '.join(PLANNER_METHODS)})")
        if not _positive_finite(sec.horizon_s):
            err("horizon_s", f"must be finite and > 0, got {sec.horizon_s}")
        if not (math.isfinite(sec.margin) and 0.5 <= sec.margin <= 1.0):
            err("margin", f"must be in [0.5, 1], got {sec.margin}")
        if sec.fit not in FITS:
            err("fit", f"unknown fit {sec.fit!r} (known: {', '.join(FITS)})")
        if not (math.isfinite(sec.tolerance) and sec.tolerance >= 0):
            err("tolerance", f"must be finite and >= 0, got {sec.tolerance}")
    elif name == "service":
        if sec.batch < 1:
            err("batch", f"must be >= 1, got {sec.batch}")
        for key_name in ("lead_s", "status_hz", "gap_timeout_s"):
            if not _positive_finite(getattr(sec, key_name)):
                err(key_name, f"must be finite and > 0, got {getattr(sec, key_name)}")
        if sec.status_hz < 5:
            err("status_hz", f"must be >= 5 (PROTOCOL.md), got {sec.status_hz}")
        for key_name in ("max_buffered_points", "max_buffered_bytes"):
            if getattr(sec, key_name) < 1:
                err(key_name, f"must be >= 1, got {getattr(sec, key_name)}")
    elif name == "gcode":
        _check_gcode(sec, err)
    elif name == "zenoh":
        if sec.mode not in ZENOH_MODES:
            err("mode", f"unknown zenoh mode {sec.mode!r} (known: {', '.join(ZENOH_MODES)})")
        for key_name in ("listen", "connect"):
            for i, ep in enumerate(getattr(sec, key_name)):
                problem = endpoint_problem(ep)
                if problem:
                    err(f"{key_name}[{i}]", problem)
        if sec.config_file and not Path(sec.config_file).is_file():
            err("config_file", f"no such file {sec.config_file!r}")


def auto_letters(axes: tuple[str, ...]) -> tuple[str, ...]:
    """The letter map a machine gets when its configuration names none: each axis named by a
    G-code axis letter is driven by that letter, except that a mandrel axis C with no A axis
    beside it is driven by A (winder CAM such as fiberpath writes the mandrel as A)."""
    out = []
    for axis in axes:
        letter = axis.strip().upper()
        if letter == "C" and "A" not in axes:
            letter = "A"
        if len(letter) == 1 and letter in GCODE_AXIS_LETTERS:
            out.append(f"{letter}:{axis}")
    return tuple(out)


def _check_gcode(sec: GcodeSection, err) -> None:
    """The letter map's own form (the axes it names are checked against the machine in
    `_check_cross`)."""
    seen: dict[str, int] = {}
    for i, pair in enumerate(sec.letters):
        letter, sep, axis = pair.partition(":")
        letter = letter.strip().upper()
        if not sep or not axis.strip():
            err(f"letters[{i}]", f"expected \"LETTER:AXIS\" such as \"A:C\", got {pair!r}")
        elif len(letter) != 1 or letter not in GCODE_AXIS_LETTERS:
            err(f"letters[{i}]", f"{letter!r} is not a G-code axis letter "
                f"({', '.join(GCODE_AXIS_LETTERS)})")
        elif letter in seen:
            err(f"letters[{i}]", f"letter {letter} is mapped twice (also letters[{seen[letter]}])")
        else:
            seen[letter] = i
    for i, letter in enumerate(sec.ignore):
        up = letter.strip().upper()
        if len(up) != 1 or up not in GCODE_AXIS_LETTERS:
            err(f"ignore[{i}]", f"{letter!r} is not a G-code axis letter "
                f"({', '.join(GCODE_AXIS_LETTERS)})")
        elif up in seen:
            err(f"ignore[{i}]", f"letter {up} is mapped to an axis by gcode.letters; it cannot "
                "also be ignored")
    if sec.dialect not in GCODE_DIALECTS:
        err("dialect", f"unknown dialect {sec.dialect!r} (known: {', '.join(GCODE_DIALECTS)})")


def _check_cross(values: dict[str, Any], source: str, errors: list[str]) -> None:
    if values["zenoh"].mode == "client" and not values["zenoh"].connect:
        errors.append(f"{source}: zenoh.connect: client mode needs at least one endpoint")
    if not values["gcode"].letters:
        return  # auto_letters: valid by construction
    axes = values["machine"].axes
    by_axis: dict[str, str] = {}
    for i, pair in enumerate(values["gcode"].letters):
        letter, _, axis = (p.strip() for p in pair.partition(":"))
        if axis not in axes:
            errors.append(f"{source}: gcode.letters[{i}]: {letter.upper()} -> {axis}, but the "
                          f"machine has no axis {axis} (machine.axes: {list(axes)})")
        elif axis in by_axis:
            errors.append(f"{source}: gcode.letters[{i}]: two letters on axis {axis} "
                          f"({by_axis[axis]} and {letter.upper()})")
        else:
            by_axis[axis] = letter.upper()
    missing = [a for a in axes if a not in by_axis]
    if missing and len(by_axis) == len(values["gcode"].letters):
        errors.append(f"{source}: gcode.letters: no letter drives axis "
                      f"{', '.join(missing)} (add e.g. \"{_letter_hint(missing[0])}:"
                      f"{missing[0]}\")")


def _letter_hint(axis: str) -> str:
    """A plausible G-code letter for a machine axis named `axis` (for error messages)."""
    up = axis.strip().upper()
    return up if len(up) == 1 and up in GCODE_AXIS_LETTERS else "B"


def endpoint_problem(endpoint: str) -> str | None:
    """None if `endpoint` is a well-formed zenoh locator, else what is wrong with it."""
    m = _ENDPOINT_RE.match(endpoint)
    if not m:
        return (f"malformed endpoint {endpoint!r}: expected PROTO/ADDRESS such as "
                "tcp/127.0.0.1:7447 (PROTO one of tcp, udp, tls, quic, ws, unixsock-stream)")
    if m["proto"] in ("tcp", "udp", "tls", "quic", "ws"):
        hp = _HOSTPORT_RE.match(m["addr"])
        if not hp:
            return f"malformed endpoint {endpoint!r}: expected HOST:PORT after {m['proto']}/"
        port = int(hp["port"])
        if not 0 <= port <= 65535:
            return f"malformed endpoint {endpoint!r}: port {port} is not in 0..65535"
    return None


def config_to_toml(cfg: Config) -> str:
    """The configuration as TOML that `load_config` reads back.

    Written by hand: the standard library reads TOML but does not write it, and our tables
    are flat (strings, numbers, booleans and arrays of those)."""
    lines: list[str] = []
    for name in _SECTIONS:
        sec = getattr(cfg, name)
        doc = (type(sec).__doc__ or "").strip().splitlines()[0]
        lines += [f"# {doc}", f"[{name}]"]
        for f in fields(sec):
            lines.append(f"{f.name} = {_toml_value(getattr(sec, f.name))}")
        lines.append("")
    return "\n".join(lines)


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"cannot write {value!r} as TOML")  # pragma: no cover


def load_config_or_exit(path: str | None) -> Config:
    """For CLIs: load, or print the errors to stderr and exit 2."""
    import sys

    try:
        return load_config(path)
    except ConfigError as exc:
        for line in exc.errors:
            print(f"config error: {line}", file=sys.stderr)
        raise SystemExit(2) from None
