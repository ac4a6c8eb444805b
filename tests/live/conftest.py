"""Live tests run on the loopback interface only.

* LSL reads a machine-only ``lsl_api.cfg`` (``LSLAPICFG``, set here before pylsl is imported): discovery
  is machine-scoped, every multicast group is 127.0.0.1, the only known peer is 127.0.0.1, IPv6 is off.
  The session id is this process's own, so that concurrent test runs never see each other's streams.
* Where the machine allows it (root, ``unshare`` and ``ip`` available), each test re-runs itself in a
  child pytest inside a private network namespace that holds only the loopback interface
  (``unshare -n``), so that nothing could leave the machine even if a library ignored the config.
"""

from __future__ import annotations

import functools
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterator

import numpy as np
import pytest

from cogblocks.live.config import machine_only_config

_INSIDE = "COGBLOCKS_LIVE_NETNS"


@functools.cache
def _namespace_command() -> tuple[str, ...] | None:
    """The command prefix that runs a program in a fresh loopback-only network namespace, or None."""
    if os.environ.get(_INSIDE) == "1" or not hasattr(os, "geteuid") or os.geteuid() != 0:
        return None
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        return None
    prefix = ("unshare", "-n", "sh", "-c", 'ip link set lo up && exec "$@"', "sh")
    probe = subprocess.run([*prefix, "true"], capture_output=True)
    return prefix if probe.returncode == 0 else None


if os.environ.get(_INSIDE) != "1":
    # the children of a namespace run read the config afresh; a run in this process needs it before pylsl
    if "pylsl" in sys.modules and _namespace_command() is None:
        raise RuntimeError("tests/live: pylsl was imported before the machine-only LSL config could be set")
    os.environ["LSLAPICFG"] = str(
        machine_only_config(tempfile.mkdtemp(prefix="cogblocks-lsl-"), f"cogblocks-test-{os.getpid()}")
    )
elif not os.path.isfile(os.environ.get("LSLAPICFG", "")):
    raise RuntimeError(f"tests/live: {_INSIDE}=1 is for the namespace runs, which inherit LSLAPICFG; it is not set")

try:
    import pylsl
except (ImportError, RuntimeError) as exc:  # pylsl raises RuntimeError when it cannot load liblsl
    pylsl = None
    _PYLSL_PROBLEM = f"pylsl cannot load liblsl: {exc}"
else:
    _PYLSL_PROBLEM = ""


# {test name: (outcome, report)} from their run in a network namespace, per folder (or per test)
_CHILD_RESULTS: dict[object, dict[str, tuple[str, str]]] = {}


def _run_in_namespace(prefix: tuple[str, ...], config: pytest.Config, nodeids: list[str]) -> dict[str, tuple]:
    """Run the tests in a child pytest inside a fresh network namespace; their outcomes by test name."""
    with tempfile.TemporaryDirectory() as tmp:
        junit = os.path.join(tmp, "junit.xml")
        command = [
            *prefix,
            sys.executable,
            "-m",
            "pytest",
            "-q",
            "-p",
            "no:randomly",
            "-p",
            "no:xdist",
            "-p",
            "no:cacheprovider",
            "-p",
            "no:hypothesispytest",
            f"--junitxml={junit}",
            *nodeids,
        ]
        env = {**os.environ, _INSIDE: "1"}
        child = subprocess.run(command, cwd=config.rootpath, env=env, capture_output=True, text=True, timeout=300)
        output = child.stdout[-6000:] + child.stderr[-2000:]
        results: dict[str, tuple[str, str]] = {}
        if os.path.exists(junit):
            for case in ET.parse(junit).getroot().iter("testcase"):
                outcome, text = "passed", ""
                for tag in ("failure", "error", "skipped"):
                    found = case.find(tag)
                    if found is not None:
                        outcome = "skipped" if tag == "skipped" else "failed"
                        text = (found.get("message") or "") + "\n" + (found.text or "")
                results[case.get("name")] = (outcome, text or output)
    return results or {"": ("failed", output)}


@pytest.hookimpl(tryfirst=True)
def pytest_pyfunc_call(pyfuncitem: pytest.Function) -> bool | None:
    prefix = _namespace_command()
    if prefix is None:
        return None  # run here, on the machine-only config alone
    here = pyfuncitem.path.parent
    key = here if "PYTEST_XDIST_WORKER" not in os.environ else pyfuncitem.nodeid
    if key not in _CHILD_RESULTS:
        # one child for every live test of the session; under xdist, where other workers run some of them,
        # one per test (test names are unique in this folder)
        neighbours = [i.nodeid for i in pyfuncitem.session.items if i.path.parent == here]
        nodeids = neighbours if key == here else [pyfuncitem.nodeid]
        _CHILD_RESULTS[key] = _run_in_namespace(prefix, pyfuncitem.config, nodeids)
    results = _CHILD_RESULTS[key]
    outcome, text = results.get(pyfuncitem.name, ("failed", next(iter(results.values()))[1]))
    if outcome == "failed":
        pytest.fail(f"failed inside a loopback-only network namespace:\n{text}", pytrace=False)
    if outcome == "skipped":
        pytest.skip(f"skipped inside the network namespace: {text.strip()}")
    return True


@pytest.fixture
def lsl():
    """The pylsl module; skips the test, with the reason, only when pylsl cannot load its library."""
    if pylsl is None:
        pytest.skip(_PYLSL_PROBLEM)
    return pylsl


@pytest.fixture
def stream_name(request) -> str:
    """A stream name of this test alone."""
    return f"{request.node.name}-{os.getpid()}".replace("[", "-").replace("]", "")


class Streamer:
    """A test outlet: pushes ``signal(t)`` at ``rate`` Hz, stamped with the LSL clock, in a thread."""

    def __init__(
        self, lsl, name: str, signal: Callable[[float], np.ndarray], channels: int, unit: str, rate: float = 100.0
    ) -> None:
        info = lsl.StreamInfo(name, "MoCap", channels, rate, lsl.cf_double64, f"{name}-source")
        chans = info.desc().append_child("channels")
        for i in range(channels):
            ch = chans.append_child("channel")
            ch.append_child_value("label", f"c{i}")
            ch.append_child_value("unit", unit)
        self.lsl = lsl
        self.outlet = lsl.StreamOutlet(info)
        self.signal = signal
        self.period = 1.0 / rate
        self.stamps: list[float] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        start = time.perf_counter()
        k = 0
        while not self._stop.is_set():
            stamp = self.lsl.local_clock()
            self.outlet.push_sample(np.atleast_1d(self.signal(stamp)), stamp)
            self.stamps.append(stamp)
            k += 1
            wait = start + k * self.period - time.perf_counter()
            if wait > 0:
                time.sleep(wait)

    def start(self) -> Streamer:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()


@pytest.fixture
def streamer(lsl) -> Iterator[Callable[..., Streamer]]:
    """Start test outlets: ``streamer(name, signal, channels=1, unit="mm")``; stopped after the test."""
    started: list[Streamer] = []

    def start(name: str, signal: Callable[[float], np.ndarray], channels: int = 1, unit: str = "mm") -> Streamer:
        s = Streamer(lsl, name, signal, channels, unit).start()
        started.append(s)
        return s

    yield start
    for s in started:
        s.stop()


class ViewServer:
    """``cogblocks view FILE --port 0`` in a subprocess: its URL once it serves; Ctrl-C ends it (``stop``)."""

    def __init__(self, path: str) -> None:
        root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        self.process = subprocess.Popen(
            [sys.executable, "-m", "cogblocks.cli", "view", str(path), "--port", "0"],
            cwd=root,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        self.line = self.process.stdout.readline()
        self.url = self.line.split(" at ")[1].split()[0] if " at http" in self.line else ""

    def get(self, what: str) -> dict:
        """The page's ``meta`` or ``data`` as JSON."""
        import json
        import urllib.request

        return json.loads(urllib.request.urlopen(self.url + what, timeout=10).read())

    def stop(self) -> tuple[int, str]:
        """Ctrl-C; the exit code and what it wrote on stderr."""
        import signal

        self.process.send_signal(signal.SIGINT)
        _, err = self.process.communicate(timeout=20)
        return self.process.returncode, err


@pytest.fixture
def view_server() -> Iterator[Callable[[str], ViewServer]]:
    """Start ``cogblocks view`` on a file: ``view_server(path)``; stopped after the test if still running."""
    started: list[ViewServer] = []

    def start(path: str) -> ViewServer:
        started.append(ViewServer(path))
        return started[-1]

    yield start
    for server in started:
        if server.process.poll() is None:
            server.stop()
