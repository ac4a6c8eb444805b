"""The inner split the optimised blender was tuned on holds no held-out movement."""

import json

import numpy as np
import torch

from cogblocks.diagrams.amplification import amplification_setup
from cogblocks.diagrams.amplification_setup import OPTIMISED
from studies.amplification_inner import evaluate, inner_setup, main

torch.set_num_threads(1)


def test_inner_split_lies_in_the_training_part():
    outer = amplification_setup(None, 1)
    inner = inner_setup(0, components=5)
    # the inner library is the outer training part: every inner movement is a training movement
    np.testing.assert_array_equal(inner.library.velocity, outer.library.velocity[outer.train])
    replayed = inner.library.velocity[inner.humans]
    held_out = outer.library.velocity[outer.val]
    assert not any(np.array_equal(r, h) for r in replayed for h in held_out)
    assert np.all(inner.library.fear[inner.humans]) and len(inner.subspace) == 5 and inner.subspace.e_des == 0
    assert set(inner.table.rows) <= set(np.flatnonzero(inner.movements.fear))  # e_des = 0: fear rows


def test_evaluate_and_command(capsys):
    row = evaluate(1, 1, 12, solver="linearised", realism=1000.0, margin=0.09, time_limit_ms=3.5)
    assert row["n"] == 1 and set(row["judges"]) == {"ensemble", "kinematic"} and row["decisions"] > 0
    assert main(["--e-des", "1", "--limit", "1"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["e_des"] == 1 and printed["components"] == 12 and printed["n"] == 1


def test_command_keeps_the_solve_ticks_option(capsys):
    assert main(["--e-des", "0", "--limit", "1", "--track-past", "1"]) == 0
    printed = json.loads(capsys.readouterr().out)
    # the option as given, and the row's count of ticks that worked on a decision under its own name
    assert printed["solve_ticks"] == OPTIMISED["solve_ticks"] and printed["track_past"] is True
    assert printed["ticks_worked"] >= printed["decisions"] > 0


def test_command_takes_kinematic_networks_from_files(capsys):
    from cogblocks.amplification.judges import BLENDER_KINEMATIC_ENSEMBLE

    files = [BLENDER_KINEMATIC_ENSEMBLE, BLENDER_KINEMATIC_ENSEMBLE]
    assert main(["--e-des", "1", "--limit", "1", "--kinematic-members", "6", "--kinematic-weights", *files]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["members"] == {"profile": 2, "kinematic": 6} and printed["kinematic_weights"] == files
    assert printed["n"] == 1 and printed["decisions"] > 0


def test_command_takes_the_eighth_round_options(capsys, monkeypatch):
    import studies.amplification_inner as inner

    calls = []
    monkeypatch.setattr(inner, "run_amplification", lambda *a, **kw: (calls.append(kw), {"optimised": {"n": 0}})[1])
    argv = ["--e-des", "0", "--limit", "1", "--emit", "tail", "--removal-margin", "0.09999"]
    assert main(argv) == 0
    printed = json.loads(capsys.readouterr().out)
    given = {"emit": "tail", "removal_margin": 0.09999}
    assert {k: printed[k] for k in given} == given
    assert {k: calls[0]["optimised"][k] for k in given} == given  # what the blender is built with


def test_command_takes_the_ninth_round_options(capsys, monkeypatch):
    import studies.amplification_inner as inner

    calls = []
    monkeypatch.setattr(inner, "run_amplification", lambda *a, **kw: (calls.append(kw), {"optimised": {"n": 0}})[1])
    assert main(["--e-des", "0", "--limit", "1", "--emit", "tail", "--guard-rest", "1", "--guard-margin", "5"]) == 0
    printed = json.loads(capsys.readouterr().out)
    given = {"emit": "tail", "guard_rest": True, "guard_margin": 5.0}
    assert {k: printed[k] for k in given} == given
    assert {k: calls[0]["optimised"][k] for k in given} == given  # what the blender is built with


def test_command_takes_the_tenth_round_options(capsys, monkeypatch):
    import studies.amplification_inner as inner

    calls = []
    monkeypatch.setattr(inner, "run_amplification", lambda *a, **kw: (calls.append(kw), {"optimised": {"n": 0}})[1])
    assert main(["--e-des", "1", "--limit", "1", "--gradient", "blocks", "--predict-setup", "0"]) == 0
    printed = json.loads(capsys.readouterr().out)
    given = {"gradient": "blocks", "predict_setup": False}
    assert {k: printed[k] for k in given} == given
    assert {k: calls[0]["optimised"][k] for k in given} == given  # what the blender is built with
