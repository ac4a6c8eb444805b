"""PoP of Amplification: the ready diagram, its validation run and the CLI."""

import json

import numpy as np
import pytest
import torch

from cogblocks.amplification import L2Amplification, NoCorrection, RLCorrector, VelocityPositionComputer
from cogblocks.cli import main
from cogblocks.diagrams.amplification import (
    PAPER,
    amplification_setup,
    plot_amplification,
    pop_amplification,
    replay_movement,
    run_amplification,
)
from cogblocks.sim import DiagramError, Simulator

torch.set_num_threads(1)  # tiny networks: threads only add contention on a shared machine


@pytest.fixture(scope="module")
def setup():
    return amplification_setup()


def replay(setup, index, **kwargs):
    lib = setup.library
    return pop_amplification(
        (lib.velocity[index], lib.position[index]), setup.movements, table=setup.table, encoder=setup.encoder, **kwargs
    )


def test_the_diagram_runs_and_blends(setup):
    human = int(setup.humans[0])
    d = replay(setup, human)
    assert isinstance(d["l2"], L2Amplification)
    trace = Simulator(d, probes={"reference": "l2.reference"}).run(n_steps=200)
    np.testing.assert_array_equal(trace["v_a"][:10], trace["v_h"][:10])  # pass-through
    reference = int(trace["reference"][-1])
    assert setup.movements.fear[reference]  # e_des = 1: the reference encodes fear
    c = trace["c"][10:, None]
    np.testing.assert_allclose(trace["v_a"][10:], c * trace["v_h"][10:] + (1 - c) * trace["v_r"][10:])
    np.testing.assert_allclose(trace["p_a"][0], trace["p_h"][0])
    assert 0.0 <= trace["eps"][-1] <= 1.0
    assert "flowchart" in d.to_mermaid()


def test_replay_movement_is_the_diagram_run_over_the_window(setup):
    human = int(setup.humans[1])
    probes = {"reference": "l2.reference"}
    by_hand = Simulator(replay(setup, human, corrector=NoCorrection()), probes=probes).run(n_steps=200)
    trace = replay_movement(setup, human, probes=probes)
    assert len(trace.t) == setup.library.max_len == 200
    for name in ("v_a", "p_a", "c", "eps", "reference"):
        np.testing.assert_array_equal(trace[name], by_hand[name])


def test_corrector_is_swappable(setup):
    d = replay(setup, int(setup.humans[1]))
    old = d.replace("l2.corrector", RLCorrector())
    assert isinstance(old, NoCorrection)
    trace = Simulator(d, probes=["l2.alpha"]).run(n_steps=200)
    assert (trace["l2.alpha"][:10] == 0).all()
    with pytest.raises(DiagramError, match="cannot replace"):
        d.replace("l2.corrector", VelocityPositionComputer())


def test_removing_fear_swaps_the_roles(setup):
    fear_val = setup.val[setup.library.fear[setup.val]]
    table = amplification_setup(None, 0).table
    lib = setup.library
    d = pop_amplification(
        (lib.velocity[fear_val[0]], lib.position[fear_val[0]]),
        setup.movements,
        table=table,
        encoder=setup.encoder,
        e_des=0,
    )
    trace = Simulator(d, probes={"reference": "l2.reference", "nearest": "l2.nearest"}).run(n_steps=60)
    assert not setup.movements.fear[int(trace["reference"][-1])]
    assert setup.movements.fear[int(trace["nearest"][-1])]
    with pytest.raises(ValueError, match="e_des"):
        pop_amplification((lib.velocity[0], lib.position[0]), setup.movements, table=table, e_des=1)


def test_run_amplification_on_a_few_movements():
    result = run_amplification(("blend", "blend_rl"), limit=3)
    assert set(result) == {"blend", "blend_rl"}
    for row in result.values():
        assert row["n"] == 3
        assert 0.0 <= row["encoded"] <= 1.0 and 0.0 <= row["terminal_ok"] <= 1.0
        assert row["final_distance_mm"] >= 0.0
    with pytest.raises(ValueError, match="unknown variant"):
        run_amplification(("blend", "optimal"), limit=1)


def test_cli_json_and_plot(capsys, tmp_path, monkeypatch):
    import cogblocks.diagrams.amplification as amplification

    # the full validation set is the example's and the docs' job: a few movements are enough here
    full = amplification.run_amplification

    def few(variants=("blend", "blend_rl", "optimised"), **kwargs):
        return full(variants, limit=4, **kwargs)

    monkeypatch.setattr(amplification, "run_amplification", few)
    plot = tmp_path / "fig6.png"
    assert main(["run", "amplification", "--json", "--plot", str(plot)]) == 0
    result = json.loads(capsys.readouterr().out)
    assert set(result) == set(PAPER) | {"optimised", "e_des_0"}
    assert set(result["e_des_0"]) == set(PAPER) | {"optimised"}
    judged = {"judges", "encoded_independent", "judges_agreement"}
    remove = result.pop("e_des_0")
    for name, row in [*result.items(), *remove.items()]:
        timing = {"solve_ms_p50", "solve_ms_p99", "decision_ms_p50", "decision_ms_p99", "solve_ticks"}
        extra = {*timing, "fallbacks", "decisions"} if name == "optimised" else set()
        assert set(row) == {"encoded", "terminal_ok", "final_distance_mm", "n", "naturalness"} | extra | judged
        assert set(row["naturalness"]["velocity_step_ratio"]) == {"median", "max"}
        assert 0.0 <= row["naturalness"]["steps_within_share"] <= 1.0
        assert row["encoded_independent"] == row["judges"]["ensemble"] and set(row["judges"]) == {
            "ensemble",
            "kinematic",
        }
    assert plot.stat().st_size > 1000
    assert main(["run", "amplification"]) == 0
    assert "paper 89 %" in capsys.readouterr().out


def test_plot_rejects_unknown_variant(tmp_path):
    with pytest.raises(ValueError, match="variant"):
        plot_amplification(str(tmp_path / "x.png"), variant="optimal")
