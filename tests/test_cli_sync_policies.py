"""``cogblocks run sync --group N``: what the main job runs, and a figure for every policy that ran."""

import json

from cogblocks.cli import main
from cogblocks.diagrams.sync import DEFAULT_MOTION, DEFAULT_MOTIONS


def test_the_main_job_runs_pop_syncs_default_motion_computer_too(capsys):
    assert main(["run", "sync", "--group", "1", "--duration", "1", "--json"]) == 0
    ran = [row["policy"] for row in json.loads(capsys.readouterr().out)["results"]]
    assert ran == [*DEFAULT_MOTIONS, DEFAULT_MOTION] and DEFAULT_MOTION == "gated"


def test_plot_draws_every_policy_that_ran(capsys, tmp_path, monkeypatch):
    import matplotlib

    monkeypatch.setitem(matplotlib.rcParams, "svg.fonttype", "none")  # text stays text, to read the legend
    plot = tmp_path / "fig.svg"
    argv = ["run", "sync", "--group", "1", "--policy", "mean", "--policy", "lookahead", "--duration", "1"]
    assert main([*argv, "--plot", str(plot)]) == 0
    err = capsys.readouterr().err
    for policy in ("mean", "lookahead"):
        drawn = tmp_path / f"fig-{policy}.svg"
        assert f"wrote {drawn}" in err and drawn.read_text().startswith("<?xml")
        assert f"with L2 ({policy})" in drawn.read_text()  # the legend names the policy drawn
