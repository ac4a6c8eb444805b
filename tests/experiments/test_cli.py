"""``cogblocks sweep sync`` and ``cogblocks run ... --save-trace``."""

import json

import numpy as np
import pandas as pd
import pytest

from cogblocks.cli import main
from cogblocks.data import groups
from cogblocks.diagrams.demo import kuramoto_diagram
from cogblocks.diagrams.sync import run_sync
from cogblocks.sim import Simulator, Trace


def test_sweep_sync_matches_run_sync(tmp_path, capsys):
    out = tmp_path / "runs.csv"
    argv = ["sweep", "sync", "--groups", "1", "--policies", "mean", "--backend", "serial", "--out", str(out)]
    assert main([*argv, "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    reference = run_sync(1, ["mean"])
    assert summary["runs"] == 2 and summary["failed"] == 0
    rows = {row["policy"]: row for row in summary["summary"]}
    assert rows["none"]["r_mean"] == reference["r_without"]
    assert rows["mean"]["r_mean"] == reference["results"][0]["r_with"]
    assert rows["mean"]["change_pct"] == pytest.approx(reference["results"][0]["change_pct"], rel=1e-12)
    df = pd.read_csv(out)
    assert df["policy"].tolist() == ["none", "mean"] and df["group"].tolist() == [1, 1]
    assert df["mean_dev_rad"].iloc[1] == pytest.approx(reference["results"][0]["mean_dev_rad"], rel=1e-12)


def test_sweep_sync_random_groups(capsys):
    code = main(["sweep", "sync", "--random", "2", "--policies", "mean", "--backend", "serial"])
    if hasattr(groups, "random_groups"):
        assert code == 0 and "held-out random groups (2" in capsys.readouterr().out
    else:
        assert code == 2
        assert "random groups need cogblocks.data.groups.random_groups" in capsys.readouterr().err


def test_sweep_sync_refuses_bad_options(capsys):
    assert main(["sweep", "sync", "--groups", "4", "--backend", "serial"]) == 2
    assert "Table 2 has groups [1, 2, 3], got [4]" in capsys.readouterr().err
    assert main(["sweep", "sync", "--scheduler", "tcp://127.0.0.1:1"]) == 2
    assert "--scheduler needs --backend dask" in capsys.readouterr().err


def test_run_demo_saves_its_trace(tmp_path):
    path = tmp_path / "demo.parquet"
    assert main(["run", "demo", "--duration", "2", "--json", "--save-trace", str(path)]) == 0
    saved = Trace.load(path)
    direct = Simulator(kuramoto_diagram()).run(n_steps=201)
    np.testing.assert_array_equal(saved.t, direct.t)
    np.testing.assert_array_equal(saved["theta"], direct["theta"])
    assert saved.units == direct.units


def test_run_sync_saves_one_policys_trace(tmp_path, capsys):
    path = tmp_path / "sync.npz"
    assert main(["run", "sync", "--group", "1", "--policy", "mean", "--json", "--save-trace", str(path)]) == 0
    result = json.loads(capsys.readouterr().out)
    saved = Trace.load(path)
    assert float(saved["r"].mean()) == result["results"][0]["r_with"]
    assert set(saved) == {"r", "theta_l2", "theta_l0"}
    assert main(["run", "sync", "--group", "1", "--save-trace", str(path)]) == 2
    assert "give exactly one --policy" in capsys.readouterr().err
