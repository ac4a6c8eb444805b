"""The scope's HTTP server: the page, its layout, and the rows of a run as Server-Sent Events or at once.

A live scope runs this module as its own process (``python -m cogblocks.live.scope_server``), reading the
rows that the tick loop writes into a file-backed ring (see :class:`~cogblocks.live.scope.Scope`), so that
serving and JSON encoding never hold the tick loop's interpreter lock. A view serves a whole run from memory.
"""

from __future__ import annotations

import json
import math
import sys
import threading
from collections.abc import Sequence
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

import numpy as np

from cogblocks.live.scope_page import PAGE

__all__ = ["HEADER", "PANELS", "REFRESH_HZ", "RingFeed", "StaticFeed", "layout", "serve"]

#: Updates sent to a live page per second.
REFRESH_HZ = 20.0
#: Floats before the ring's rows: rows written so far, capacity, row width.
HEADER = 3
#: The page's panels: title and the series drawn in it, in this order (absent series are left out).
PANELS = (
    ("inputs", ("sample",)),
    ("phases (rad)", ("theta", "theta_l2", "theta_l0")),
    ("θ_L2 − θ_L0 (rad)", ("theta_l2_minus_l0",)),
    ("λ (rad)", ("lam",)),
    ("r", ("r",)),
    ("late ticks (cumulative)", ("late",)),
)


def layout(names: Sequence[str], units: dict[str, str], title: str, mode: str) -> dict[str, Any]:
    """The page's layout: its title, mode (``live`` or ``view``) and panels."""
    series = {n: units.get(n) or "" for n in names}
    if "theta_l2" in series and "theta_l0" in series:
        series["theta_l2_minus_l0"] = "rad"
    series["late"] = "ticks"
    panels = [(title_, [s for s in group if s in series]) for title_, group in PANELS]
    placed = {s for _, group in panels for s in group}
    panels += [(f"{n} ({series[n]})" if series[n] else n, [n]) for n in series if n not in placed]
    return {
        "title": title,
        "mode": mode,
        "refresh_hz": REFRESH_HZ,
        "panels": [{"title": t, "series": group} for t, group in panels if group],
    }


def _json_rows(x: np.ndarray) -> list[list[float | None]]:
    return [[v if math.isfinite(v) else None for v in row] for row in x.tolist()]


def message(t: np.ndarray, late: np.ndarray, columns: dict[str, np.ndarray], ticks: int) -> dict[str, Any]:
    """Rows as the page reads them: per series a list of rows (NaN as null); θ_L2 − θ_L0 when both are there."""
    out: dict[str, Any] = {"t": t.tolist(), "late": [[int(v)] for v in late]}
    for name, x in columns.items():
        out[name] = _json_rows(x)
    if "theta_l2" in columns and "theta_l0" in columns:
        out["theta_l2_minus_l0"] = _json_rows(np.angle(np.exp(1j * (columns["theta_l2"] - columns["theta_l0"]))))
    out["ticks"] = ticks
    return out


class StaticFeed:
    """A whole run, served at once (``/data``)."""

    def __init__(self, meta: dict[str, Any], data: dict[str, Any]) -> None:
        self.meta, self.data = meta, data


class RingFeed:
    """The rows that a live run writes into a file-backed ring of float64 (see :class:`~cogblocks.live.scope.Scope`)."""

    def __init__(self, path: str, meta: dict[str, Any], sizes: dict[str, int]) -> None:
        self.meta, self.sizes = meta, sizes
        self.data = None
        head = np.memmap(path, dtype=np.float64, mode="r", shape=(HEADER,))
        self.capacity, self.width = int(head[1]), int(head[2])
        self._all = np.memmap(path, dtype=np.float64, mode="r", shape=(HEADER + self.capacity * self.width,))
        self._rows = self._all[HEADER:].reshape(self.capacity, self.width)

    def since(self, seq: int) -> tuple[dict[str, Any] | None, int]:
        """The rows from ``seq`` on (at most the ring's capacity) as a message, and the next ``seq``."""
        written = int(self._all[0])
        if written <= seq:
            return None, seq
        first = max(seq, written - self.capacity + 1)  # the oldest row may be being overwritten: skip it
        index = np.arange(first, written) % self.capacity
        rows = np.array(self._rows[index])
        columns, at = {}, 2
        for name, size in self.sizes.items():
            columns[name] = rows[:, at : at + size]
            at += size
        return message(rows[:, 0], rows[:, 1], columns, written), written


def serve(feed: RingFeed | StaticFeed, port: int, stop: threading.Event) -> ThreadingHTTPServer:
    """An HTTP server on 127.0.0.1:``port`` for ``feed`` (not started: call ``serve_forever``)."""

    class Handler(BaseHTTPRequestHandler):
        def log_message(self, *args: Any) -> None:  # the terminal is the run's
            pass

        def _send(self, body: bytes, kind: str) -> None:
            self.send_response(200)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            self.wfile.write(body)

        def do_GET(self) -> None:  # noqa: N802 - the name http.server calls
            if self.path == "/":
                self._send(PAGE.encode("utf-8"), "text/html; charset=utf-8")
            elif self.path == "/meta":
                self._send(json.dumps(feed.meta).encode(), "application/json")
            elif self.path == "/data" and isinstance(feed, StaticFeed):
                self._send(json.dumps(feed.data).encode(), "application/json")
            elif self.path == "/events" and isinstance(feed, RingFeed):
                self._events()
            else:
                self.send_error(404)

        def _events(self) -> None:
            self.send_response(200)
            self.send_header("Content-Type", "text/event-stream")
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            seq = 0
            try:
                while not stop.wait(1.0 / REFRESH_HZ):
                    payload, seq = feed.since(seq)
                    if payload is not None:
                        self.wfile.write(f"data: {json.dumps(payload)}\n\n".encode())
                    else:
                        self.wfile.write(b": idle\n\n")  # a comment: a closed page shows as a broken pipe
                    self.wfile.flush()
            except (BrokenPipeError, ConnectionResetError):
                pass  # the page was closed

    server = ThreadingHTTPServer(("127.0.0.1", port), Handler)
    server.daemon_threads = True
    return server


def main(argv: list[str] | None = None) -> int:
    """``python -m cogblocks.live.scope_server RING PORT LAYOUT``: serve a live ring until stdin closes."""
    ring, port, spec = (argv if argv is not None else sys.argv[1:])[:3]
    spec = json.loads(spec)
    stop = threading.Event()
    try:
        server = serve(RingFeed(ring, spec["meta"], spec["sizes"]), int(port), stop)
    except OSError as exc:
        print(f"error: cannot serve on 127.0.0.1:{port} ({exc})", flush=True)
        return 1
    print(f"http://127.0.0.1:{server.server_address[1]}/", flush=True)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    sys.stdin.read()  # the run closes our stdin when it ends, or dies
    stop.set()
    server.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
