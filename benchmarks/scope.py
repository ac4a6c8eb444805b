"""The scope's cost to the 100 Hz loop: tick p99 of the live sync diagram with the scope served and read, and without.

The live sync diagram (``live_sync``, group 1, the ``mean`` motion computer: a cheap tick, so the scope's
share shows most) runs at 100 Hz on an LSL stream of this process (loopback only, the machine-only
configuration), alternately without a scope and with one whose page a client in another process reads
(Server-Sent Events at 20 Hz, as a browser would; the server is a process of its own). Runs
alternate, so that the machine's load falls on both.

* ``scope.tick_ms_p99``: 99th percentile of the tick's computation with the scope; reference: the same
  without it (pooled over the runs of each kind). The ratio is the scope's cost; the aim is <= 1.1. On a
  machine whose cores are busy with other work, the server's process competes with the loop for a core.
* ``scope.push_us``: what the loop itself pays, :meth:`Scope.push` of one tick of this diagram (median of
  20000 calls); reference: the median tick without the scope.

    python benchmarks/run.py --only scope [--quick]      (6 runs of 10 s; 4 of 4 s with --quick)
"""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from collections.abc import Iterator

import numpy as np

from cogblocks.live.config import use_machine_only_config

DT = 0.01
_CLIENT = """
import sys, urllib.request
with urllib.request.urlopen(sys.argv[1] + "events") as events:
    for line in events:
        pass
"""


def _stream(name: str, stop: threading.Event) -> None:
    import pylsl

    from cogblocks.data.groups import TABLE2

    omega = np.asarray(TABLE2[1].omega)
    info = pylsl.StreamInfo(name, "Phase", len(omega), 100.0, pylsl.cf_double64, f"{name}-bench")
    channels = info.desc().append_child("channels")
    for _ in omega:
        channels.append_child("channel").append_child_value("unit", "rad")
    outlet = pylsl.StreamOutlet(info)
    start, k = time.perf_counter(), 0
    while not stop.is_set():
        stamp = pylsl.local_clock()
        outlet.push_sample(np.mod(omega * stamp, 2 * np.pi), stamp)
        k += 1
        time.sleep(max(0.0, start + k * DT - time.perf_counter()))


def _run(name: str, seconds: float, with_scope: bool) -> np.ndarray:
    from cogblocks.live import live_sync, run_realtime
    from cogblocks.live.scope import Scope

    compiled = live_sync(name, f"{name}-l2-{int(with_scope)}", group=1, motion="mean", timeout=30.0).compile(DT)
    scope = client = None
    if with_scope:
        scope = Scope.for_diagram(compiled)
        client = subprocess.Popen([sys.executable, "-c", _CLIENT, scope.url])
        time.sleep(1.0)  # the client connected
    try:
        report = run_realtime(compiled, seconds, 1.0 / DT, scope=scope)
    finally:
        for block in compiled.blocks.values():
            if hasattr(block, "close"):
                block.close()
        if scope is not None:
            scope.close()
            client.kill()
            client.wait()
    return report.tick_ms


def run(quick: bool = False) -> Iterator[dict]:
    import os

    if "LSLAPICFG" not in os.environ:
        use_machine_only_config(f"bench-scope-{os.getpid()}")
    seconds = 4.0 if quick else 10.0
    name = f"bench-scope-{os.getpid()}"
    stop = threading.Event()
    threading.Thread(target=_stream, args=(name, stop), daemon=True).start()
    ticks: dict[bool, list[np.ndarray]] = {False: [], True: []}
    try:
        for with_scope in (False, True) * (2 if quick else 3):
            ticks[with_scope].append(_run(name, seconds, with_scope))
        push = 1e3 * _push_ms(name)  # while the stream still runs: the diagram resolves it
    finally:
        stop.set()
    plain = float(np.percentile(np.concatenate(ticks[False]), 99))
    scoped = float(np.percentile(np.concatenate(ticks[True]), 99))
    yield {"name": "scope.tick_ms_p99", "value": scoped, "unit": "ms", "reference": plain, "ratio": scoped / plain}
    median = float(np.median(np.concatenate(ticks[False])))
    yield {
        "name": "scope.push_us",
        "value": push,
        "unit": "us",
        "reference": 1e3 * median,
        "ratio": push / (1e3 * median),
    }


def _push_ms(name: str) -> float:
    """Median time of one push of a tick of the sync diagram's outputs, in ms."""
    from cogblocks.live import live_sync
    from cogblocks.live.scope import Scope

    compiled = live_sync(name, f"{name}-push", group=1, motion="mean", timeout=30.0).compile(DT)
    row = compiled.step()
    for block in compiled.blocks.values():
        if hasattr(block, "close"):
            block.close()
    scope = Scope.for_diagram(compiled)
    try:
        times = np.empty(20000)
        for i in range(len(times)):
            began = time.perf_counter()
            scope.push(i * DT, row, False)
            times[i] = time.perf_counter() - began
    finally:
        scope.close()
    return 1e3 * float(np.median(times))
