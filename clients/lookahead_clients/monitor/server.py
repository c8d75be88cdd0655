"""The monitor's web side: the standard library's ThreadingHTTPServer (no dependency).

Routes:
- `GET /` and `/static/<file>`: the page (package data, works offline);
- `GET /api/machines`: the watched machines' specs (axes, units, limits);
- `GET /api/state?machine=ID`: one machine's snapshot (JSON; for scripts and tests);
- `GET /api/boot.js`: the same first picture as a script (`window.MONITOR_BOOT`), so the
  page draws before its load event (and a browser dumping the DOM at load sees it);
- `GET /api/stream`: Server-Sent Events, one `update` event per push interval holding every
  machine's snapshot since this client's cursors (chart rows, events, the path once);
- `POST /api/cmd/<machine>/<verb>` with an optional JSON body `{"value": f}`: a PROTOCOL.md
  command; the reply is `{"ok", "error", "by"}`;
- `GET /api/health`: `{"ok": true, "sse_clients": n}`.

Each SSE client has its own thread that reads the views and writes; a client that goes
away (write error or timeout) ends its thread, and the bus side never waits for one.
"""

from __future__ import annotations

import json
import logging
import os
import threading
import time
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from urllib.parse import parse_qs, urlparse

from lookahead.protocol import COMMANDS

log = logging.getLogger("lookahead.monitor")

#: SSE push interval (s): 10 updates per second is smooth enough for a status page and
#: costs the monitor a few kB per client per push
PUSH_S = 0.1
#: a client whose socket takes longer than this to accept a write is dropped (s)
WRITE_TIMEOUT_S = 10.0
#: chart rows sent to a client that just connected (its backlog; the ring holds more)
BACKLOG_ROWS = 1500
STATIC = {"index.html": "text/html; charset=utf-8", "monitor.js": "text/javascript",
          "monitor.css": "text/css"}


class MonitorServer(ThreadingHTTPServer):
    """HTTP server over `views` (id -> MachineView) and `bus` (a MonitorBus or anything with
    `command(machine, verb, value) -> dict`)."""

    daemon_threads = True
    allow_reuse_address = True

    def __init__(self, address: tuple[str, int], views: dict, bus) -> None:
        super().__init__(address, Handler)
        self.views = views
        self.bus = bus
        self.sse_clients = 0
        self.sse_served = 0
        self._count_lock = threading.Lock()
        self.stopping = threading.Event()
        self.instance = f"{os.getpid()}-{time.time_ns()}"

    @property
    def url(self) -> str:
        host, port = self.server_address[:2]
        return f"http://{host}:{port}/"

    def sse_delta(self, delta: int) -> None:
        with self._count_lock:
            self.sse_clients += delta
            if delta > 0:
                self.sse_served += 1


def _static(name: str) -> bytes:
    return resources.files("lookahead_clients.monitor").joinpath("static", name).read_bytes()


class Handler(BaseHTTPRequestHandler):
    server: MonitorServer
    protocol_version = "HTTP/1.1"

    def log_message(self, fmt: str, *args) -> None:  # quiet: the access log goes to debug
        log.debug("%s " + fmt, self.address_string(), *args)

    def _send(self, code: int, body: bytes, ctype: str) -> None:
        self.send_response(code)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        self.wfile.write(body)

    def _json(self, obj, code: int = 200) -> None:
        self._send(code, json.dumps(obj).encode(), "application/json")

    def do_GET(self) -> None:
        url = urlparse(self.path)
        path = url.path
        if path in ("/", "/index.html"):
            self._send(200, _static("index.html"), STATIC["index.html"])
        elif path.startswith("/static/") and path[8:] in STATIC:
            self._send(200, _static(path[8:]), STATIC[path[8:]])
        elif path == "/api/machines":
            self._json([v.spec.to_json() for v in self.server.views.values()])
        elif path == "/api/state":
            ids = parse_qs(url.query).get("machine") or list(self.server.views)[:1]
            view = self.server.views.get(ids[0])
            if view is None:
                self._json({"error": f"unknown machine {ids[0]!r}"}, 404)
            else:
                self._json(view.snapshot())
        elif path == "/api/health":
            self._json({"ok": True, "sse_clients": self.server.sse_clients,
                        "sse_served": self.server.sse_served})
        elif path == "/api/stream":
            self._stream()
        elif path == "/api/boot.js":
            boot = {"hello": self._hello(),
                    "update": [v.snapshot(max(v.chart.next_id - BACKLOG_ROWS, 0))
                               for v in self.server.views.values()]}
            self._send(200, f"window.MONITOR_BOOT = {json.dumps(boot)};\n".encode(),
                       STATIC["monitor.js"])
        else:
            self._json({"error": f"no such page {path}"}, 404)

    def do_POST(self) -> None:
        parts = urlparse(self.path).path.strip("/").split("/")
        if len(parts) != 4 or parts[:2] != ["api", "cmd"]:
            self._json({"error": "expected POST /api/cmd/<machine>/<verb>"}, 404)
            return
        machine, verb = parts[2], parts[3]
        length = int(self.headers.get("Content-Length") or 0)
        body = self.rfile.read(length) if length else b""
        if machine not in self.server.views:
            self._json({"ok": False, "error": f"unknown machine {machine!r}", "by": "monitor"},
                       404)
            return
        if verb not in COMMANDS:
            self._json({"ok": False, "by": "monitor",
                        "error": f"verb must be one of {', '.join(COMMANDS)}, got {verb!r}"},
                       400)
            return
        try:
            data = json.loads(body) if body.strip() else {}
            value = data.get("value") if isinstance(data, dict) else None
            value = None if value is None else float(value)
        except (ValueError, TypeError) as exc:
            self._json({"ok": False, "error": f"bad JSON body: {exc}", "by": "monitor"}, 400)
            return
        self._json(self.server.bus.command(machine, verb, value))

    def _stream(self) -> None:
        self.send_response(HTTPStatus.OK)
        self.send_header("Content-Type", "text/event-stream")
        self.send_header("Cache-Control", "no-store")
        self.send_header("Connection", "close")
        self.end_headers()
        self.close_connection = True
        self.connection.settimeout(WRITE_TIMEOUT_S)
        views = self.server.views
        cursors = {mid: {"row": max(v.chart.next_id - BACKLOG_ROWS, 0), "event": 0,
                         "path": None, "report": -1} for mid, v in views.items()}
        self.server.sse_delta(+1)
        try:
            self._event("hello", self._hello())
            while not self.server.stopping.is_set():
                update = []
                for mid, view in views.items():
                    c = cursors[mid]
                    snap = view.snapshot(c["row"], c["event"], c["path"])
                    c["row"], c["event"] = snap["next_row"], snap["next_event"]
                    if "path" in snap:
                        c["path"] = (snap["path"]["job"], snap["path"]["version"])
                    if snap["report_id"] == c["report"]:
                        snap["report"] = None  # sent already
                    c["report"] = snap["report_id"]
                    update.append(snap)
                self._event("update", update)
                time.sleep(PUSH_S)
        except (OSError, ValueError):  # the browser went away (or its socket timed out)
            pass
        finally:
            self.server.sse_delta(-1)

    def _hello(self) -> dict:
        """The machines, and which monitor process serves them (a page that reconnects to
        the same one keeps what it has; to a restarted one, it starts over)."""
        return {"instance": self.server.instance,
                "machines": [v.spec.to_json() for v in self.server.views.values()]}

    def _event(self, name: str, data) -> None:
        self.wfile.write(f"event: {name}\ndata: {json.dumps(data)}\n\n".encode())
        self.wfile.flush()
