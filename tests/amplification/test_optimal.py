"""Optimisation-based blending: the casadi network, the resampling map, the block in the architecture."""

import copy
import json
import math

import numpy as np
import pytest
import torch

from cogblocks.amplification import VelocityBlender
from cogblocks.amplification.encoder_casadi import encoder_to_casadi, input_map
from cogblocks.cli import main
from cogblocks.data.features import resample_movement
from cogblocks.diagrams.amplification import DELTA_POS_MM, amplification_setup, pop_amplification, run_amplification
from cogblocks.sim import Simulator
from tests.amplification.optimal_helpers import plain_blender

torch.set_num_threads(1)
FIRST_DECISION = 10  # ΔT: the projector's first decision shows from this tick on


@pytest.fixture(scope="module")
def setup():
    return amplification_setup()


def replay(setup, human, blending=None):
    lib = setup.library
    d = pop_amplification(
        (lib.velocity[human], lib.position[human]), setup.movements, table=setup.table, encoder=setup.encoder,
        blending=blending,
    )  # fmt: skip
    return d, Simulator(d, probes={"decision": "encoder.decision"}).run(n_steps=lib.max_len)


def test_casadi_network_equals_torch(setup):
    network = setup.encoder
    x = network.mean.double().numpy() + network.scale.double().numpy() * np.random.default_rng(0).normal(size=(50, 60))
    reference = copy.deepcopy(network).double()  # the casadi function is float64 throughout
    reference.train()  # predict() must switch to evaluation mode: no dropout
    expected = reference.predict(x)
    eps = encoder_to_casadi(network)
    logit = encoder_to_casadi(network, logit=True)
    got = np.array([float(eps(row)) for row in x])
    assert np.abs(got - expected).max() < 1e-9
    with torch.no_grad():
        z = reference.out(torch.relu(reference.preactivation(torch.as_tensor(x)))).squeeze(-1).numpy()
    assert np.abs(np.array([float(logit(row)) for row in x]) - z).max() < 1e-9
    # the smooth model the solver uses lies above the exact logit by at most ln 2/β per hidden unit
    beta = 10.0
    smooth = encoder_to_casadi(network, logit=True, sharpness=beta)
    gap = np.array([float(smooth(row)) for row in x]) - z
    assert np.abs(gap).max() <= math.log(2) / beta * network.out.weight.abs().sum().item() + 1e-12


@pytest.mark.parametrize("length", [1, 2, 3, 4, 5, 37, 200])
def test_input_map_equals_resample_movement(length):
    velocity = np.random.default_rng(length).normal(scale=300.0, size=(length, 3))
    got = input_map(length) @ velocity.T.reshape(-1)
    np.testing.assert_allclose(got, resample_movement(velocity, length), rtol=0, atol=1e-9)


def test_same_ports_as_velocity_blender(setup):
    table_based = VelocityBlender(setup.table)
    optimal = plain_blender(setup.movements, setup.encoder, setup.table)
    assert {n: p.declared for n, p in optimal.inputs.items()} == {n: p.declared for n, p in table_based.inputs.items()}
    assert {n: p.spec for n, p in optimal.outputs.items()} == {n: p.spec for n, p in table_based.outputs.items()}


@pytest.mark.parametrize("position", [0, 3])
def test_plan_meets_both_constraints(setup, position):
    human = setup.humans[position]
    blender = plain_blender(setup.movements, setup.encoder, setup.table, time_limit_ms=1000.0)
    _, trace = replay(setup, human, blender)
    # pass-through before the first decision
    np.testing.assert_array_equal(trace["v_a"][:FIRST_DECISION], trace["v_h"][:FIRST_DECISION])
    np.testing.assert_array_equal(trace["c"][:FIRST_DECISION], 1.0)
    assert blender.results[0].tick == FIRST_DECISION
    planned = [r for r in blender.results if r.status != "ended"]
    assert all(r.status == "converged" for r in planned) and blender.fallbacks == 0
    final = planned[-1]
    assert final.eps > 0.9 and final.distance_mm <= DELTA_POS_MM
    # and the movement actually emitted meets them too
    assert trace["decision"][-1] == 1
    assert np.linalg.norm(trace["p_a"][-1] - trace["p_h"][-1]) <= DELTA_POS_MM
    assert len(blender.solve_ms) == len(planned) and np.all(blender.solve_ms > 0)


def test_fallback_to_the_table_when_out_of_time(setup):
    # for this movement no warm start passes the acceptance check: no plan is ever made
    human = setup.humans[0]
    blender = plain_blender(setup.movements, setup.encoder, setup.table, time_limit_ms=1e-6)
    _, trace = replay(setup, human, blender)
    statuses = [r.status for r in blender.results]
    assert "converged" not in statuses
    assert blender.fallbacks == statuses.count("fallback") > 0
    assert blender.end == 0  # no plan was ever made: the table's c throughout
    _, table_trace = replay(setup, human)
    np.testing.assert_allclose(trace["v_a"], table_trace["v_a"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(trace["c"], table_trace["c"], rtol=0, atol=0)


def test_fallback_keeps_the_previous_plan(setup, monkeypatch):
    human = setup.humans[3]
    d, _ = replay(setup, human, plain_blender(setup.movements, setup.encoder, setup.table, time_limit_ms=1000.0))
    sim = Simulator(d)
    ticks = 35  # three plans made
    sim.run(n_steps=ticks)
    block = d["l2.blender"]
    plan, end = block.plan.copy(), block.end
    assert end > ticks and block.fallbacks == 0
    no_plan = lambda blender, problem, guess: (None, np.zeros(4), "fallback")  # noqa: E731
    monkeypatch.setattr("cogblocks.amplification.decision.solve_decision", no_plan)  # no solve converges from now on
    tail = sim.run(n_steps=setup.library.max_len - ticks)
    later = [r for r in block.results if r.tick >= ticks]
    assert block.fallbacks == sum(r.status == "fallback" for r in later) > 0
    assert all(r.status in ("fallback", "ended") for r in later)
    np.testing.assert_array_equal(block.plan, plan)
    t = np.arange(ticks, setup.library.max_len)
    inside = t < end
    np.testing.assert_allclose(tail["v_a"][inside], tail["v_h"][inside] + plan[t[inside]], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(tail["v_a"][~inside], 0.0)


def test_swappable_with_replace(setup):
    human = setup.humans[3]
    options = dict(time_limit_ms=1000.0)
    _, direct = replay(setup, human, plain_blender(setup.movements, setup.encoder, setup.table, **options))
    d, _ = replay(setup, human)
    old = d.replace("l2.blender", plain_blender(setup.movements, setup.encoder, setup.table, **options))
    assert isinstance(old, VelocityBlender)
    swapped = Simulator(d).run(n_steps=setup.library.max_len)
    np.testing.assert_allclose(swapped["v_a"], direct["v_a"], rtol=0, atol=1e-9)


def test_run_amplification_and_cli(monkeypatch, capsys):
    import cogblocks.diagrams.amplification as amplification

    result = run_amplification(("optimised",), limit=1)
    row = result["optimised"]
    judged = {"judges", "encoded_independent", "judges_agreement"}
    assert (
        set(row)
        == {
            "encoded",
            "terminal_ok",
            "final_distance_mm",
            "n",
            "solve_ms_p50",
            "solve_ms_p99",
            "fallbacks",
            "decisions",
            "decision_ms_p50",
            "decision_ms_p99",
            "solve_ticks",
            "naturalness",
        }
        | judged
    )
    assert row["n"] == 1 and 0 < row["solve_ms_p50"] <= row["solve_ms_p99"]
    # a decision's CPU time is the sum over its ticks: never below one tick's
    assert row["solve_ticks"] >= row["decisions"] and row["decision_ms_p99"] >= row["solve_ms_p50"]
    monkeypatch.setattr(
        amplification, "run_amplification", lambda *args, **kwargs: run_amplification(*args, **kwargs, limit=1)
    )
    assert main(["run", "amplification", "--json", "--variant", "blend", "--variant", "optimised"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert list(printed) == ["blend", "optimised", "e_des_0"] and "solve_ms_p99" in printed["optimised"]
    assert list(printed["e_des_0"]) == ["blend", "optimised"] and "solve_ms_p99" in printed["e_des_0"]["optimised"]
    assert main(["run", "amplification", "--variant", "optimised"]) == 0
    assert "CPU time per tick p50" in capsys.readouterr().out
