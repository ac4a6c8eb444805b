"""SettledHandover: the person's phase until the estimate has settled, then a slewed hand-over to θ_L2."""

import numpy as np
import pytest

from cogblocks.blocks.angles import TWO_PI
from cogblocks.data.groups import TABLE2
from cogblocks.diagrams.sync import pop_sync
from cogblocks.sim import Diagram, Simulator
from cogblocks.sync import SettledHandover

N, ASSISTED, SLEW, DT = 3, 1, 2.0, 0.01


def run(theta, theta_l2, settled, slew=SLEW):
    d = Diagram()
    block = d.add("avatar", SettledHandover(N, ASSISTED, slew=slew))
    for name in ("theta", "theta_l2", "settled"):
        d.expose_input(name, block.inputs[name])
    inputs = {"theta": theta, "theta_l2": theta_l2, "settled": settled}
    return Simulator(d, dt=DT, probes={"shown": "avatar.theta_avatar"}).run(n_steps=len(theta_l2), inputs=inputs)


def ramps(n_steps, alteration):
    t = np.arange(n_steps) * DT
    theta = np.stack([(w * t) % TWO_PI for w in (3.0, 4.0, 5.0)], axis=1)
    return theta, (theta[:, ASSISTED] + alteration) % TWO_PI


def test_the_avatar_is_the_person_then_slews_onto_theta_l2_and_stays_on_it():
    n_steps, settle, alteration = 300, 100, 1.01  # not a whole number of slew steps: no tie to round
    theta, theta_l2 = ramps(n_steps, alteration)
    settled = np.zeros((n_steps, N), dtype=bool)
    settled[settle:200, ASSISTED] = True  # unsettled again later: the hand-over never goes back
    settled[:settle, [0, 2]] = True  # the others' estimates do not count
    shown = np.asarray(run(theta, theta_l2, settled)["shown"])
    person = theta[:, ASSISTED]
    # independently: the offset grows by slew·dt per tick from the settling tick on, and the avatar is θ_L2
    # from the first tick the offset it starts from is within one step of the alteration
    ticks = np.arange(n_steps)
    before = np.clip((ticks - settle) * SLEW * DT, 0.0, None)
    reached = int(np.argmax(alteration - before <= SLEW * DT))
    expected = np.where(ticks < settle, person, (person + before + SLEW * DT) % TWO_PI)
    np.testing.assert_allclose(shown[:reached], expected[:reached], rtol=0, atol=1e-12)
    assert np.array_equal(shown[reached:], theta_l2[reached:])  # θ_L2 itself from then on
    steps = np.abs(np.angle(np.exp(1j * np.diff(shown - person))))
    assert steps.max() <= SLEW * DT + 1e-12


def test_a_hand_over_takes_the_short_way_round():
    theta, theta_l2 = ramps(200, -3.0)  # θ_L2 3 rad behind: the offset goes down, not 3.28 rad up
    settled = np.ones((200, N), dtype=bool)
    shown = np.asarray(run(theta, theta_l2, settled)["shown"])
    offsets = np.angle(np.exp(1j * (shown - theta[:, ASSISTED])))
    assert offsets[:100].max() <= 0.0
    assert np.array_equal(shown[-1:], theta_l2[-1:])


def test_a_non_finite_input_holds_the_avatar():
    theta, theta_l2 = ramps(50, 0.5)
    theta_l2[20:25] = np.nan
    theta[30, ASSISTED] = np.inf
    shown = np.asarray(run(theta, theta_l2, np.zeros((50, N), dtype=bool))["shown"])
    assert np.all(shown[20:25] == shown[19]) and shown[30] == shown[29]
    np.testing.assert_array_equal(shown[25:30], theta[25:30, ASSISTED])


@pytest.mark.parametrize("group", [1, 3])
def test_in_pop_sync_the_avatar_shows_the_true_phase_until_the_assisted_estimate_settles(group):
    d = pop_sync(group, motion="mean", domain="position")
    assisted = d["avatar"].assisted
    probes = {"shown": "avatar.theta_avatar", "theta": "group.theta", "l2": "l2.theta_l2",
              "settled": f"sensing.estimator{assisted}.algorithm.settled"}  # fmt: skip
    trace = Simulator(d, probes=probes).run(duration=8.0)
    settled = np.asarray(trace["settled"], dtype=bool)
    first = int(np.argmax(settled))
    assert 0 < first < len(settled) - 100  # the estimate settles within the run, not at once
    shown, person = np.asarray(trace["shown"]), np.asarray(trace["theta"])[:, assisted]
    np.testing.assert_array_equal(shown[:first], person[:first])
    assert np.array_equal(shown[-100:], np.asarray(trace["l2"])[-100:])


def test_without_the_hand_over_the_group_sees_theta_l2_as_before():
    d = pop_sync(1, motion="mean", domain="position", handover=False)
    assert "avatar" not in d.blocks
    trace = Simulator(d, probes={"seen": "seen.y", "l2": "l2.theta_l2"}).run(duration=2.0)
    assert np.array_equal(np.asarray(trace["seen"])[:, TABLE2[1].assisted], np.asarray(trace["l2"]))
