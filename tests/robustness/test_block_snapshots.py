"""Every catalogued block declares its whole state: a snapshot taken mid-run and restored continues bit for bit.

The blocks, their valid parameters and how to feed them come from the bad-data harness's ``FACTORIES``
(tests/robustness/test_block_properties.py), which covers every public block; here they get clean
streams, and :func:`cogblocks.sim.check_block` compares the continuation from a restored snapshot with
an uninterrupted run and names any attribute that changed between ticks without being declared.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import cogblocks.catalogue as catalogue
from cogblocks.sim import Block, StateCheck, UndeclaredStateError, check_block
from tests.robustness.test_block_properties import FACTORIES, case_id, concrete


def test_every_catalogued_block_is_covered():
    assert set(catalogue.public_blocks().values()) <= set(FACTORIES)


@pytest.mark.parametrize("cls", [pytest.param(cls, id=case_id(cls, "")) for cls in FACTORIES])
@settings(max_examples=2, deadline=None, derandomize=True, database=None)
@given(data=st.data())
def test_a_restored_snapshot_continues_bit_for_bit(cls, data):
    fac = FACTORIES[cls]
    block = data.draw(fac.block, label="block")
    feeds = fac.feeds(block)
    n = data.draw(st.integers(12, 24), label="ticks")
    streams = {name: data.draw(feed.stream(n, ()), label=name) for name, feed in feeds.items()}
    if fac.couple is not None:
        streams = fac.couple(block, streams)
    specs = {name: concrete(block.inputs[name], feed.spec) for name, feed in feeds.items()}
    at = data.draw(st.integers(1, n - 1), label="snapshot at")
    report = check_block(block, streams, n_steps=n, snapshot_at=at, specs=specs, raise_error=False)
    assert report.ok, report.message()


class Counter(Block):
    """Counts ticks, but keeps the count in an ordinary attribute instead of declared state."""

    def __init__(self) -> None:
        super().__init__()
        self.add_output("y", shape=(), dtype=float, unit="1", wrapped=False)
        self.count = 0

    def output(self, k: int) -> None:
        self.y.value[...] = self.count

    def update(self, k: int) -> None:
        self.count += 1


class DeclaredCounter(Counter):
    def __init__(self) -> None:
        Block.__init__(self)
        self.add_output("y", shape=(), dtype=float, unit="1", wrapped=False)
        self.add_state("count", 0)


def test_a_block_with_undeclared_state_is_named_and_its_wrong_continuation_shown():
    with pytest.raises(UndeclaredStateError) as caught:
        check_block(Counter(), n_steps=8, snapshot_at=5)
    message = str(caught.value)
    assert "Counter keeps state in undeclared attribute(s) ['count']" in message
    assert "add_state" in message
    # the uninterrupted run counts 5, 6, 7 from tick 5; the restored one goes on from where it had got to
    assert "output 'y' at tick 5 is 8.0, the uninterrupted run gave 5.0" in message
    report = check_block(Counter(), n_steps=8, snapshot_at=5, raise_error=False)
    assert report == StateCheck("Counter", 5, 8, ("count",), report.mismatch) and not report.ok


def test_the_same_block_with_declared_state_passes_and_the_original_is_untouched():
    block = DeclaredCounter()
    report = check_block(block, n_steps=8, snapshot_at=5)
    assert report.ok and report.message() == ""
    assert block.count == 0  # the check ran copies


def test_fed_inputs_per_tick_and_constant():
    from cogblocks.blocks import Integrator, Sum

    ramp = np.arange(10.0)
    assert check_block(Sum("+-"), {"u0": ramp, "u1": 1.0}, n_steps=10).ok
    assert check_block(Integrator(), {"u": ramp}, n_steps=10, snapshot_at=9).ok


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"inputs": {"v": 1.0}}, r"Integrator has no input\(s\) \['v'\]; it has \['u'\]"),
        ({"inputs": {"u": 1.0}, "n_steps": 1}, "n_steps must be an integer >= 2"),
        ({"inputs": {"u": 1.0}, "n_steps": 5, "snapshot_at": 5}, r"snapshot_at must be an integer in \[1, 5\)"),
    ],
)
def test_bad_arguments_are_refused_naming_them(kwargs, match):
    from cogblocks.blocks import Integrator

    with pytest.raises(ValueError, match=match):
        check_block(Integrator(), **kwargs)
