"""A scope in the browser: a run's outputs as they go (``cogblocks live --scope``) or a saved run (``cogblocks view``).

The page is served by the standard library (``http.server`` on 127.0.0.1) and fed by Server-Sent
Events at :data:`REFRESH_HZ`; it draws on HTML canvases with its own few lines of JavaScript, so the
scope needs no package, no plotting library and no internet. The tick loop only appends each tick's
outputs to a bounded buffer (:meth:`Scope.push`); the server's threads read and serve it.
"""

from __future__ import annotations

import collections
import json
import math
import threading
from collections.abc import Mapping, Sequence
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

import numpy as np

from cogblocks.live.scope_page import PAGE

__all__ = ["PANELS", "REFRESH_HZ", "Scope"]

#: Updates sent to a live page per second.
REFRESH_HZ = 20.0
#: The page's panels: title and the series drawn in it, in this order (absent series are left out).
PANELS = (
    ("inputs", ("sample",)),
    ("phases (rad)", ("theta", "theta_l2", "theta_l0")),
    ("θ_L2 − θ_L0 (rad)", ("theta_l2_minus_l0",)),
    ("λ (rad)", ("lam",)),
    ("r", ("r",)),
    ("late ticks (cumulative)", ("late",)),
)
# outputs about the inlet's timing, not the run's content
_HIDDEN = {"age_ms", "fresh"}


def _floats(x: Any) -> list[float | None]:
    return [v if math.isfinite(v) else None for v in np.asarray(x, dtype=np.float64).ravel().tolist()]


class Scope:
    """Serve a page that plots a run: live (rows pushed by the tick loop) or a whole saved run.

    Parameters
    ----------
    names : sequence of str
        The outputs to show (each tick's row holds them).
    units : mapping of str to str
        Their units, for the legends.
    port : int
        TCP port on 127.0.0.1 (0: any free port; see :attr:`url`).
    capacity : int
        Ticks kept for a page that connects late (a minute at 100 Hz by default).
    title : str
        Shown at the top of the page.

    Attributes
    ----------
    url : str
        Where the page is served.
    """

    def __init__(
        self,
        names: Sequence[str],
        units: Mapping[str, str],
        *,
        port: int = 0,
        capacity: int = 6000,
        title: str = "cogblocks",
    ) -> None:
        if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
            raise ValueError(f"Scope: port must be an integer in [0, 65535], got {port!r}")
        self.names = [n for n in names if n not in _HIDDEN]
        self.units = {n: units.get(n) or "" for n in self.names}
        self.title = title
        self._rows: collections.deque = collections.deque(maxlen=capacity)
        self._lock = threading.Lock()
        self._seq = 0
        self._late = 0
        self._static: dict[str, Any] | None = None
        self._closed = threading.Event()
        try:
            self._server = ThreadingHTTPServer(("127.0.0.1", port), self._handler())
        except OSError as exc:
            raise ValueError(f"Scope: cannot serve on 127.0.0.1:{port} ({exc})") from None
        self._server.daemon_threads = True
        self.url = f"http://127.0.0.1:{self._server.server_address[1]}/"
        self._thread = threading.Thread(target=self._server.serve_forever, name="cogblocks scope", daemon=True)
        self._thread.start()

    # -- the tick loop's side: one append under an uncontended lock ------------------------
    def push(self, t: float, row: Mapping[str, Any], late: bool) -> None:
        """Add one tick (its time, its outputs as ``CompiledDiagram.step`` returned them, whether it was late)."""
        with self._lock:
            self._late += bool(late)
            self._rows.append((self._seq, t, row, self._late))
            self._seq += 1

    @classmethod
    def of_run(
        cls,
        t: np.ndarray,
        signals: Mapping[str, np.ndarray],
        units: Mapping[str, str],
        late: np.ndarray | None = None,
        **kw: Any,
    ) -> Scope:
        """A scope of a whole saved run, drawn with a time slider (``cogblocks view``)."""
        scope = cls(list(signals), units, **kw)
        rows = [{name: signals[name][i] for name in scope.names} for i in range(len(t))]
        flags = np.zeros(len(t), dtype=bool) if late is None else np.asarray(late, dtype=bool)
        scope._static = scope._message(
            list(zip(range(len(t)), t.tolist(), rows, np.cumsum(flags).tolist(), strict=True))
        )
        return scope

    def close(self) -> None:
        """Stop serving."""
        self._closed.set()
        self._server.shutdown()
        self._server.server_close()
        self._thread.join()

    # -- the server's side ---------------------------------------------------------------
    def _meta(self) -> dict[str, Any]:
        series = {n: self.units[n] for n in self.names}
        if "theta_l2" in series and "theta_l0" in series:
            series["theta_l2_minus_l0"] = "rad"
        series["late"] = "ticks"
        panels = [(title, [s for s in names if s in series]) for title, names in PANELS]
        placed = {s for _, names in panels for s in names}
        panels += [(f"{n} ({series[n]})" if series[n] else n, [n]) for n in series if n not in placed]
        return {
            "title": self.title,
            "mode": "live" if self._static is None else "view",
            "refresh_hz": REFRESH_HZ,
            "panels": [{"title": title, "series": names} for title, names in panels if names],
        }

    def _since(self, seq: int) -> tuple[list[tuple], int]:
        with self._lock:
            rows = [r for r in self._rows if r[0] >= seq] if self._rows and self._rows[-1][0] >= seq else []
        return rows, (rows[-1][0] + 1 if rows else seq)

    def _message(self, rows: list[tuple]) -> dict[str, Any]:
        out: dict[str, Any] = {"t": [r[1] for r in rows], "late": [[r[3]] for r in rows]}
        for name in self.names:
            out[name] = [_floats(r[2][name]) for r in rows]
        if "theta_l2" in self.names and "theta_l0" in self.names:
            d = [np.angle(np.exp(1j * (np.ravel(r[2]["theta_l2"]) - np.ravel(r[2]["theta_l0"])))) for r in rows]
            out["theta_l2_minus_l0"] = [_floats(x) for x in d]
        out["ticks"] = rows[-1][0] + 1 if rows else 0
        return out

    def _handler(self) -> type[BaseHTTPRequestHandler]:
        scope = self

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
                    self._send(json.dumps(scope._meta()).encode(), "application/json")
                elif self.path == "/data" and scope._static is not None:
                    self._send(json.dumps(scope._static).encode(), "application/json")
                elif self.path == "/events" and scope._static is None:
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
                    while not scope._closed.wait(1.0 / REFRESH_HZ):
                        rows, seq = scope._since(seq)
                        if rows:
                            payload = json.dumps(scope._message(rows))
                            self.wfile.write(f"data: {payload}\n\n".encode())
                        else:
                            self.wfile.write(b": idle\n\n")  # a comment keeps the connection checked
                        self.wfile.flush()
                except (BrokenPipeError, ConnectionResetError):
                    pass  # the page was closed

        return Handler
