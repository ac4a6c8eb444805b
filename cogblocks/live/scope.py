"""A scope in the browser: a run's outputs as they go (``cogblocks live --scope``) or a saved run (``cogblocks view``).

The page is served by the standard library (``http.server`` on 127.0.0.1) and fed by Server-Sent
Events at :data:`~cogblocks.live.scope_server.REFRESH_HZ`; it draws on HTML canvases with its own few
lines of JavaScript, so the scope needs no package, no plotting library and no internet. During a live
run the tick loop only writes each tick's outputs into a bounded ring of floats in a memory-mapped file
(:meth:`Scope.push`); a server in another process reads the ring and serves the page, so that its work
never holds this process's interpreter lock.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import threading
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from cogblocks.live.scope_server import HEADER, StaticFeed, layout, message, serve

__all__ = ["Scope", "ScopeView"]

# outputs about the inlet's timing, not the run's content
_HIDDEN = {"age_ms", "fresh"}


def _port(owner: str, port: Any) -> int:
    if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
        raise ValueError(f"{owner}: port must be an integer in [0, 65535], got {port!r}")
    return port


class Scope:
    """Serve a page that plots a live run; the tick loop calls :meth:`push` once per tick.

    Parameters
    ----------
    names : sequence of str
        The outputs to show (each tick's row holds them).
    units : mapping of str to str
        Their units, for the legends.
    sizes : mapping of str to int, optional
        Values per output (default: 1 each); give the compiled diagram's, e.g. via :meth:`for_diagram`.
    port : int
        TCP port on 127.0.0.1 (0: any free port; see :attr:`url`).
    capacity : int
        Ticks kept in the ring (a minute at 100 Hz by default): a page that connects late starts there.
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
        sizes: Mapping[str, int] | None = None,
        *,
        port: int = 0,
        capacity: int = 6000,
        title: str = "cogblocks",
    ) -> None:
        port = _port("Scope", port)
        self.names = [n for n in names if n not in _HIDDEN]
        sizes = {n: int((sizes or {}).get(n, 1)) for n in self.names}
        self._slices = []
        at = 2  # columns 0 and 1: time, late ticks so far
        for n in self.names:
            self._slices.append((n, at, at + sizes[n]))
            at += sizes[n]
        width = at
        handle, self._path = tempfile.mkstemp(prefix="cogblocks-scope-", suffix=".ring", dir=_ring_folder())
        os.close(handle)
        self._ring = np.memmap(self._path, dtype=np.float64, mode="w+", shape=(HEADER + capacity * width,))
        self._ring[:HEADER] = (0, capacity, width)
        # plain ndarray views of the map: indexing a memmap object costs a few microseconds a time
        self._head = np.asarray(self._ring[:HEADER])
        self._rows = np.asarray(self._ring[HEADER:]).reshape(capacity, width)
        self._capacity, self._seq, self._late = capacity, 0, 0
        spec = {"meta": layout(self.names, dict(units), title, "live"), "sizes": sizes}
        self._server = subprocess.Popen(
            [sys.executable, "-m", "cogblocks.live.scope_server", self._path, str(port), json.dumps(spec)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        line = self._server.stdout.readline().strip()
        if not line.startswith("http://"):
            self.close()
            raise ValueError(f"Scope: {line or 'the server did not start'}")
        self.url = line

    @classmethod
    def for_diagram(cls, compiled: Any, **kw: Any) -> Scope:
        """A scope of every output of a compiled diagram."""
        names = list(compiled.output_names)
        specs = {n: compiled.output_port(n).spec for n in names}
        return cls(
            names, {n: s.unit for n, s in specs.items()}, {n: math.prod(s.shape) for n, s in specs.items()}, **kw
        )

    def push(self, t: float, row: Mapping[str, Any], late: bool) -> None:
        """Add one tick: its time, its outputs (as ``CompiledDiagram.step`` returns them), whether it was late."""
        self._late += bool(late)
        line = self._rows[self._seq % self._capacity]
        line[0] = t
        line[1] = self._late
        for name, a, b in self._slices:
            value = row[name]
            line[a:b] = value if isinstance(value, float) else np.ravel(value)
        self._seq += 1
        self._head[0] = self._seq  # after the row: the server reads only complete rows

    def close(self) -> None:
        """Stop the server and remove the ring."""
        if self._server.poll() is None:
            self._server.stdin.close()
            try:
                self._server.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self._server.kill()
                self._server.wait()
        self._server.stdout.close()
        del self._rows, self._head, self._ring
        if os.path.exists(self._path):
            os.unlink(self._path)


def _ring_folder() -> str | None:
    return "/dev/shm" if os.path.isdir("/dev/shm") and os.access("/dev/shm", os.W_OK) else None


class ScopeView:
    """Serve a page that shows a whole saved run with a time slider (``cogblocks view``), from this process.

    Parameters
    ----------
    t : numpy.ndarray, shape (n,)
        Tick times.
    signals : mapping of str to numpy.ndarray
        The outputs, first axis the ticks.
    units : mapping of str to str
    late : numpy.ndarray of bool, optional
        Which ticks were late.
    port : int
    title : str
    """

    def __init__(
        self,
        t: np.ndarray,
        signals: Mapping[str, np.ndarray],
        units: Mapping[str, str],
        late: np.ndarray | None = None,
        *,
        port: int = 0,
        title: str = "cogblocks",
    ) -> None:
        port = _port("ScopeView", port)
        names = [n for n in signals if n not in _HIDDEN]
        n = len(t)
        flags = np.zeros(n, dtype=bool) if late is None else np.asarray(late, dtype=bool)
        columns = {name: np.asarray(signals[name], dtype=np.float64).reshape(n, -1) for name in names}
        data = message(np.asarray(t, dtype=np.float64), np.cumsum(flags), columns, n)
        self._stop = threading.Event()
        try:
            self._server = serve(StaticFeed(layout(names, dict(units), title, "view"), data), port, self._stop)
        except OSError as exc:
            raise ValueError(f"ScopeView: cannot serve on 127.0.0.1:{port} ({exc})") from None
        self.url = f"http://127.0.0.1:{self._server.server_address[1]}/"
        self._thread = threading.Thread(target=self._server.serve_forever, name="cogblocks view", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop serving."""
        self._stop.set()
        self._server.shutdown()
        self._server.server_close()
        self._thread.join()
