"""The blender comparison: specs, the summary against the groups' own rows, and the command line."""

import json

import numpy as np
import pytest

from cogblocks.data.groups import SyncGroup
from cogblocks.diagrams.naturalness import phase_naturalness
from cogblocks.diagrams.sync import pop_sync, simulate
from cogblocks.experiments.sync_naturalness import blender_from_spec, compare_blenders, main
from cogblocks.sync import Blender

GROUP = SyncGroup(name="three", n=3, gain=0.4, omega=(1.0, 1.6, 2.4), assisted=0, duration=4.0)


def test_blender_specs():
    assert blender_from_spec("deliverable") == ("deliverable", None)
    name, blender = blender_from_spec('soft=cogblocks.sync:Blender:{"saturation": "smooth"}')
    assert name == "soft" and isinstance(blender, Blender) and blender.saturation == "smooth"
    with pytest.raises(ValueError, match="cannot find cogblocks.sync:Nope"):
        blender_from_spec("x=cogblocks.sync:Nope")
    with pytest.raises(ValueError, match="NAME=MODULE:CALLABLE"):
        blender_from_spec("x=cogblocks.sync")


def test_summary_agrees_with_an_independent_run():
    specs = ["deliverable", 'soft=cogblocks.sync:Blender:{"saturation": "smooth"}']
    result = compare_blenders([GROUP], ["mean"], specs)
    reference, soft = result["summary"]
    assert (reference["blender"], reference["gain_kept"], soft["blender"]) == ("deliverable", 1.0, "soft")
    trace = simulate(
        pop_sync(GROUP, motion="mean", blender=Blender(saturation="smooth")),
        401,
        {"theta_l2": "l2.theta_l2", "theta_l0": "l2.theta_l0"},
        label="test",
    )
    without = simulate(pop_sync(GROUP, l2=False), 401, label="test")["r"].mean()
    change = 100 * (trace["r"].mean() - without) / without
    assert soft["mean_change_pct"] == pytest.approx(change)
    assert soft["gain_kept"] == pytest.approx(change / reference["mean_change_pct"])
    figures = phase_naturalness(trace["theta_l2"], trace["theta_l0"])
    assert soft["max_step_rad"] == pytest.approx(figures["max_step_rad"])
    assert soft["jump_free_share"] == float(figures["jumps_per_min"] == 0)
    with pytest.raises(ValueError, match="unknown policy 'nope'"):
        compare_blenders([GROUP], ["nope"], specs)


def test_command_line(capsys):
    assert main(["--random", "1", "--split", "validation", "--max-duration", "3", "--policy", "mean", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    (row,) = out["summary"]
    assert row["groups"] == 1 and row["policy"] == "mean" and np.isfinite(row["max_step_rad"])


def test_ctrl_c_keeps_the_groups_done(capsys, monkeypatch):
    """Ctrl-C after the second group (injected into the real run) prints both groups' summary and their lines."""
    import cogblocks.experiments.sync_naturalness as module

    real, calls = module.evaluate_group, []

    def interrupted_on_the_third_group(*args):
        calls.append(args[0].name)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(*args)

    monkeypatch.setattr(module, "evaluate_group", interrupted_on_the_third_group)
    argv = ["--random", "4", "--split", "validation", "--max-duration", "2", "--policy", "mean", "--json"]
    assert main(argv) == 130
    out, err = capsys.readouterr()
    result = json.loads(out)
    assert result["interrupted"] is True and result["n_requested"] == 4
    assert [g["name"] for g in result["groups"]] == calls[:2]
    (row,) = result["summary"]
    assert row["groups"] == 2
    changes = [g["results"][0]["change_pct"] for g in result["groups"]]
    assert row["mean_change_pct"] == pytest.approx(np.mean(changes), rel=1e-12)
    lines = [line for line in err.splitlines() if line.startswith("group ")]
    assert [line.split(":")[0] for line in lines] == ["group 1/4 done", "group 2/4 done"]
    assert err.rstrip().endswith("interrupted by Ctrl-C")
