"""Tests marked ``realtime`` judge work against the wall clock, so they run with the machine to themselves.

Under ``pytest -n`` every other test holds a shared lock while it runs and a ``realtime`` test takes it
exclusively: the other workers finish the test they are in and wait. A turnstile taken before the shared lock
keeps a waiting ``realtime`` test from being starved by workers that start new tests.

Whether a threaded decision finishes within its period still depends on the machine, so a live planner is
judged against the offline run that replays its recorded timeline (fixture ``replayed_planner``), not against
a run that assumes no decision was late.
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


class _ReplayedFuture:
    """A decision computed when it was started, taken when the live run took it."""

    def __init__(self, block, result, taken: int) -> None:
        self.block, self._result, self.taken = block, result, taken

    def done(self) -> bool:
        return 0 <= self.taken <= self.block.now

    def result(self, timeout: float | None = None):
        return self._result


class _ReplayExecutor:
    """Stands in for the planner's worker thread: runs a decision at once, hands it over at its recorded tick."""

    def __init__(self, block) -> None:
        self.block = block

    def submit(self, decide, *task):
        started, taken = self.block.recorded[len(self.block.timeline)]
        assert started == self.block.now, f"the replay started a decision at tick {self.block.now}, live at {started}"
        return _ReplayedFuture(self.block, decide(*task), taken)

    def shutdown(self, wait: bool = True, cancel_futures: bool = False) -> None:
        pass


@pytest.fixture
def replayed_planner():
    """A factory of :class:`~cogblocks.sync.RecedingPlanMotion` that decides offline as a threaded one did live.

    ``replayed_planner(timeline, *args, **options)``: ``timeline`` is the live block's ``timeline``; every decision
    starts at the tick it started live, and its plan is taken at the tick the live block took it (never, if it
    never did), so late decisions are late again and the plans are the live ones whatever the machine's speed.
    """
    from cogblocks.sync import RecedingPlanMotion

    class ReplayedPlanMotion(RecedingPlanMotion):
        def __init__(self, timeline, *args, **options) -> None:
            super().__init__(*args, worker="thread", **options)
            self.recorded, self.now = list(timeline), -1

        def update(self, k: int) -> None:
            self.now = k
            if self._executor is None:
                self._executor = _ReplayExecutor(self)
            super().update(k)

    return ReplayedPlanMotion
