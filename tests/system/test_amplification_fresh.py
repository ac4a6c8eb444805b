"""The shipped chain evaluated on a freshly generated library (studies.amplification_fresh)."""

import json

import numpy as np
import pytest
import torch

from cogblocks.amplification import NoCorrection
from cogblocks.data.reach import generate_reach_library
from cogblocks.diagrams.amplification import SMOOTHING_HZ, amplification_setup, pop_amplification
from cogblocks.diagrams.amplification_setup import OPTIMISED, amplification_judges
from cogblocks.sim import Simulator
from studies.amplification_fresh import FRESH_SEED, fresh_setup, main, real_shares, run_fresh

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def humans():
    return generate_reach_library(FRESH_SEED, n_subjects=2, n_fear=2, n_no_fear=2)


def test_fresh_setup_replays_only_fresh_movements_through_the_shipped_chain(humans):
    shipped = amplification_setup(None, 0)
    setup = fresh_setup(FRESH_SEED, 0, humans)
    np.testing.assert_array_equal(setup.library.velocity[setup.train], shipped.movements.velocity)
    np.testing.assert_array_equal(setup.library.velocity[setup.val], humans.velocity)
    assert setup.movements is shipped.movements and setup.table is shipped.table and setup.encoder is shipped.encoder
    assert setup.subspace is shipped.subspace
    # the fear humans of the fresh library, none of them a movement of the shipped library
    np.testing.assert_array_equal(setup.library.fear[setup.humans], True)
    assert len(setup.humans) == 2
    assert not any(np.array_equal(h, m) for h in setup.library.velocity[setup.humans] for m in shipped.library.velocity)
    with pytest.raises(ValueError, match="window and step"):
        fresh_setup(FRESH_SEED, 1, generate_reach_library(1, n_subjects=1, n_fear=1, n_no_fear=1, max_len=190))


def test_run_fresh_matches_replaying_by_hand(humans):
    rows = run_fresh(FRESH_SEED, ("blend",), limit=1, humans=humans)
    assert rows["library_seed"] == FRESH_SEED and rows["blend"]["n"] == 1 and rows["e_des_0"]["blend"]["n"] == 1
    shipped = amplification_setup(None, 1)
    first = int(np.flatnonzero(~humans.fear)[0])  # the first no-fear human is the one made to encode fear
    d = pop_amplification(
        (humans.velocity[first], humans.position[first]), shipped.movements, table=shipped.table,
        encoder=shipped.encoder, corrector=NoCorrection(), e_des=1, seed=len(shipped.movements) + first,
    )  # fmt: skip
    trace = Simulator(d).run(n_steps=humans.max_len)
    distance = float(np.linalg.norm(trace["p_a"][-1] - trace["p_h"][-1]))
    assert rows["blend"]["final_distance_mm"] == pytest.approx(distance)
    assert set(rows["blend"]) >= {"encoded", "terminal_ok", "judges", "encoded_independent", "judges_agreement"}


def test_command_prints_both_directions(capsys):
    assert main(["--limit", "1", "--variants", "blend", "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["library_seed"] == FRESH_SEED and printed["blend"]["n"] == 1 and "e_des_0" in printed
    assert main(["--limit", "1", "--variants", "blend", "--e-des", "0"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 1 and lines[0].startswith("remove fear blend: encoded ") and lines[0].endswith("n 1")


def test_share_replays_a_stratified_part(humans):
    rows = run_fresh(FRESH_SEED, ("blend",), share=0.5, humans=humans)
    # half of each class of the 2 + 2 movements: one no-fear human encodes fear, one fear human has it removed
    assert rows["share"] == 0.5 and rows["blend"]["n"] == 1 and rows["e_des_0"]["blend"]["n"] == 1


def test_run_fresh_constrains_the_networks_and_settings_asked_for(humans, monkeypatch):
    import studies.amplification_fresh as fresh
    from cogblocks.diagrams.amplification_setup import CONSTRAINED_MEMBERS, OPTIMISED

    calls = []
    run = fresh.run_amplification
    monkeypatch.setattr(fresh, "run_amplification", lambda *a, **kw: (calls.append(kw), run(*a, **kw))[1])
    rows = run_fresh(FRESH_SEED, ("blend",), limit=1, humans=humans, directions=(0,), members={"kinematic": 1},
                     optimised={"solve_ticks": 4, "components": 5})  # fmt: skip
    assert rows["e_des_0"]["blend"]["n"] == 1
    run_fresh(FRESH_SEED, ("blend",), limit=1, humans=humans, directions=(0,))
    changed, shipped = calls
    # the encoder, the shipped profile networks and 1 kinematic one; by default the shipped counts
    profile, kinematic = [60] * (1 + CONSTRAINED_MEMBERS["profile"]), [66] * CONSTRAINED_MEMBERS["kinematic"]
    assert [n.hidden.in_features for n in changed["blender_networks"]] == [*profile, 66]
    assert [n.hidden.in_features for n in shipped["blender_networks"]] == profile + kinematic
    assert changed["optimised"] == {**{k: v for k, v in OPTIMISED.items() if k != "components"}, "solve_ticks": 4}
    assert shipped["optimised"] == {k: v for k, v in OPTIMISED.items() if k != "components"}
    assert len(changed["setup"].subspace) == 5 and changed["setup"].subspace.e_des == 0
    assert shipped["setup"].subspace is amplification_setup(None, 0).subspace


def test_real_shares_are_the_judges_on_the_real_movements(humans):
    rows = real_shares(FRESH_SEED, humans)
    judges = amplification_judges()
    for name, fear in (("fear", True), ("no_fear", False)):
        movements = humans.velocity[humans.fear == fear]
        assert rows[name]["n"] == len(movements) == 2  # the fixture: 2 movements of each class
        for judge in ("ensemble", "kinematic"):  # one movement at a time: 1 fear, 0 no fear, −1 undecided
            decided = np.array([judges.decide(m[None])[judge][0] for m in movements])
            assert rows[name][judge]["correct"] == pytest.approx(np.mean(decided == int(fear)))
            assert rows[name][judge]["wrong"] == pytest.approx(np.mean(decided == 1 - int(fear)))
    assert rows["no_fear"]["kinematic"]["correct"] + rows["no_fear"]["kinematic"]["wrong"] == pytest.approx(1.0)


def test_command_passes_the_eighth_round_options(monkeypatch, capsys):
    import studies.amplification_fresh as fresh

    calls = []
    monkeypatch.setattr(fresh, "run_fresh", lambda *a, **kw: (calls.append(kw), {"library_seed": 1})[1])
    argv = ["--json", "--emit", "tail", "--removal-margin", "0.09999"]
    assert main(argv) == 0
    given = {"emit": "tail", "removal_margin": 0.09999}
    assert {k: calls[0]["optimised"][k] for k in given} == given
    monkeypatch.setattr(fresh, "real_shares", lambda seed: {"library_seed": seed, "fear": {}})
    assert main(["--library-seed", "3", "--real"]) == 0 and len(calls) == 1
    assert json.loads(capsys.readouterr().out.splitlines()[-1]) == {"library_seed": 3, "fear": {}}


def test_command_passes_the_ninth_round_options(monkeypatch):
    import studies.amplification_fresh as fresh

    calls = []
    monkeypatch.setattr(fresh, "run_fresh", lambda *a, **kw: (calls.append(kw), {"library_seed": 1})[1])
    assert main(["--json", "--emit", "tail", "--guard-rest", "1", "--guard-margin", "2.5"]) == 0
    assert main(["--json"]) == 0
    given, default = (call["optimised"] for call in calls)
    assert (given["emit"], given["guard_rest"], given["guard_margin"]) == ("tail", True, 2.5)
    assert (default["guard_rest"], default["guard_margin"]) == (OPTIMISED["guard_rest"], 0.0)  # the shipped setting


def test_command_passes_the_tenth_round_options(monkeypatch):
    import studies.amplification_fresh as fresh

    calls = []
    monkeypatch.setattr(fresh, "run_fresh", lambda *a, **kw: (calls.append(kw), {"library_seed": 1})[1])
    argv = ["--json", "--gradient", "blocks", "--predict-setup", "0", "--margin", "0.0999", "--time-limit-ms", "3.5"]
    assert main(argv) == 0
    assert main(["--json"]) == 0
    given, default = (call["optimised"] for call in calls)
    assert (given["gradient"], given["predict_setup"], given["margin"]) == ("blocks", False, 0.0999)
    assert (given["time_limit_ms"], default["time_limit_ms"]) == (3.5, OPTIMISED["time_limit_ms"])
    shipped = (OPTIMISED.get("gradient", "blocks"), OPTIMISED.get("predict_setup", True), OPTIMISED["margin"])
    assert (default["gradient"], default["predict_setup"], default["margin"]) == shipped


def test_command_passes_the_thirteenth_round_options(monkeypatch):
    import studies.amplification_fresh as fresh

    calls = []
    monkeypatch.setattr(fresh, "run_fresh", lambda *a, **kw: (calls.append(kw), {"library_seed": 1})[1])
    assert main(["--json", "--neighbours", "1", "--terminal-margin", "5"]) == 0
    assert main(["--json"]) == 0
    given, default = (call["optimised"] for call in calls)
    assert (given["neighbours"], given["terminal_margin"]) == (1, 5.0)
    shipped = (OPTIMISED["neighbours"], OPTIMISED["terminal_margin"])
    assert (default["neighbours"], default["terminal_margin"]) == shipped


def test_command_passes_the_front_end(monkeypatch):
    import studies.amplification_fresh as fresh

    calls = []
    monkeypatch.setattr(fresh, "run_fresh", lambda *a, **kw: (calls.append(kw), {"library_seed": 1})[1])
    assert main(["--json", "--front-end", "kalman", "--noise-mm", "0.3"]) == 0
    assert main(["--json"]) == 0
    assert [(c["front_end"], c["noise_mm"]) for c in calls] == [("kalman", 0.3), ("recorded", 0.0)]


def test_a_kalman_front_end_reaches_the_replays():
    # one movement through the tracker: noise changes what the block sees, so the replay differs from the recorded one
    rows = [
        run_fresh(2027, ["blend"], limit=1, directions=[1], front_end=front, noise_mm=noise)["blend"]
        for front, noise in (("recorded", 0.0), ("kalman", 1.0))
    ]
    assert rows[0]["n"] == rows[1]["n"] == 1
    assert rows[0]["final_distance_mm"] != rows[1]["final_distance_mm"]


def test_command_passes_the_smoothing(monkeypatch, capsys):
    import studies.amplification_fresh as fresh

    calls = []
    monkeypatch.setattr(fresh, "run_fresh", lambda *a, **kw: (calls.append(kw), {"library_seed": 1})[1])
    for given in (["--smoothing-hz", "5"], ["--smoothing-hz", "none"], ["--smoothing-hz", "auto"], []):
        assert main(["--json", "--front-end", "kalman", *given]) == 0
    assert [c["smoothing_hz"] for c in calls] == [5.0, None, "auto", SMOOTHING_HZ]
    with pytest.raises(SystemExit):
        main(["--json", "--smoothing-hz", "fast"])
    assert "a cut-off in Hz, 'auto' or 'none', got 'fast'" in capsys.readouterr().err
