"""Tests marked ``realtime`` judge work against the wall clock, so they run with the machine to themselves.

Under ``pytest -n`` every other test holds a shared lock while it runs and a ``realtime`` test takes it
exclusively: the other workers finish the test they are in and wait. A turnstile taken before the shared lock
keeps a waiting ``realtime`` test from being starved by workers that start new tests.
"""

import fcntl
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest


def _lock_path(name: str) -> Path:
    # one pair of lock files per pytest run: xdist workers share the controller's testrun_uid
    run = os.environ["PYTEST_XDIST_TESTRUNUID"]
    return Path(tempfile.gettempdir()) / f"cogblocks-tests-{run}-{name}.lock"


@pytest.fixture(autouse=True)
def _machine_share(request: pytest.FixtureRequest) -> Iterator[None]:
    # only an xdist worker shares the machine with others (a child pytest a live test starts is not one)
    if not hasattr(request.config, "workerinput"):
        yield
        return
    realtime = request.node.get_closest_marker("realtime") is not None
    with open(_lock_path("turnstile"), "a") as turnstile, open(_lock_path("machine"), "a") as machine:
        fcntl.flock(turnstile, fcntl.LOCK_EX)
        if not realtime:
            fcntl.flock(turnstile, fcntl.LOCK_UN)
        fcntl.flock(machine, fcntl.LOCK_EX if realtime else fcntl.LOCK_SH)
        if realtime:
            fcntl.flock(turnstile, fcntl.LOCK_UN)
        try:
            yield
        finally:
            fcntl.flock(machine, fcntl.LOCK_UN)
