"""Traps a user meets when writing a block of their own: bad port fields, swapping it into a ready
diagram, an algebraic loop made by a default ``feedthrough=True``."""

import numpy as np
import pytest

from cogblocks.blocks.angles import TWO_PI
from cogblocks.blocks.specs import PHASE
from cogblocks.diagrams.sync import pop_sync
from cogblocks.sim import Block, DiagramError, Simulator


class _Ports(Block):
    def __init__(self, **fields):
        super().__init__()
        self.add_input("x", **fields)


@pytest.mark.parametrize(
    ("fields", "parameter"),
    [({"shape": "three", "unit": 5}, "shape"), ({"shape": (3,), "unit": 5}, "unit"), ({"shape": 2.5}, "shape")],
)
def test_a_bad_port_field_names_the_block_the_port_and_the_parameter(fields, parameter):
    with pytest.raises(ValueError) as caught:
        _Ports(**fields)
    message = str(caught.value)
    assert message.startswith("_Ports.x:"), message
    assert f"{parameter} must be" in message
    assert "invalid literal" not in message


class NoisyKuramoto(Block):
    """A user's Kuramoto plant without the optional ``omega`` input; ``feedthrough`` of θ_L2 is a choice."""

    def __init__(self, omega, gain, assisted, feedthrough=False):
        super().__init__()
        self.omega0 = np.asarray(omega, dtype=float)
        self.gain = gain
        self.assisted = assisted
        n = len(self.omega0)
        self.add_input("theta_l2", PHASE, feedthrough=feedthrough)
        self.add_output("theta", PHASE.with_(shape=(n,)))
        self.add_state("phase", np.zeros(n))

    def output(self, k):
        self.theta.value[...] = self.phase

    def update(self, k):
        seen = self.phase.copy()
        seen[self.assisted] = float(self.theta_l2.value)
        pull = np.sin(seen[None, :] - seen[:, None]).sum(axis=1)
        self.phase = np.mod(self.phase + self.dt * (self.omega0 + self.gain * pull), TWO_PI)


def _custom_group(d, feedthrough=False):
    old = d["group"]
    return NoisyKuramoto(old.omega0, old.gain, old.assisted, feedthrough=feedthrough)


def test_replace_allows_a_block_without_ports_nobody_wired_and_warns_which():
    d = pop_sync(3, motion="mean")
    with pytest.warns(UserWarning, match=r"'group'.*NoisyKuramoto.*omega"):
        d.replace("group", _custom_group(d))
    trace = Simulator(d, probes=["group.theta"]).run(n_steps=20)
    assert np.isfinite(trace["group.theta"]).all()


def test_replace_still_refuses_a_block_without_a_wired_port():
    d = pop_sync(3, motion="mean")

    class NoTheta(Block):
        def __init__(self):
            super().__init__()
            self.add_input("theta_l2", PHASE, feedthrough=False)

    with pytest.raises(DiagramError, match=r"cannot replace 'group'.*theta"):
        d.replace("group", NoTheta())
    assert type(d["group"]).__name__ == "KuramotoGroup"  # the diagram is unchanged


def test_an_algebraic_loop_names_the_newest_block_whose_input_could_be_non_feedthrough():
    d = pop_sync(3, motion="mean")
    with pytest.warns(UserWarning):
        d.replace("group", _custom_group(d, feedthrough=True))
    with pytest.raises(DiagramError) as caught:
        d.compile()
    message = str(caught.value)
    assert "algebraic loop" in message and "feedthrough=False" in message
    hint = message[message.index("feedthrough=False") :]
    # the user's block, the newest on the loop, is named before the older library blocks on it
    assert hint.index("group.theta_l2 (NoisyKuramoto)") < hint.index("l2.blender.theta_l0 (Blender)"), message
