"""The random-group generator, the constant-frequency bound and the held-out evaluation (API and CLI)."""

import dataclasses
import json

import numpy as np
import pytest
from scipy.sparse.csgraph import connected_components

from cogblocks.cli import main
from cogblocks.data.groups import TABLE2, SyncGroup, locking_gain, random_groups
from cogblocks.diagrams.sync import run_sync
from cogblocks.evaluation.sync_bound import constant_frequency_scan, upper_bound
from cogblocks.evaluation.sync_heldout import evaluate_group, heldout_table, plot_heldout
from cogblocks.sync import SyncModel
from cogblocks.sync.model import order_parameter

KEYS = {
    "policy",
    "lowered_share",
    "mean_change_pct",
    "p5_change_pct",
    "worst_change_pct",
    "mean_bound_fraction",
    "mean_dev_rad",
    "max_dev_rad",
    "max_step_rad",
    "mean_jumps_per_min",
    "jump_free_share",
    "max_peak_speed_ratio",
}


def test_generator_is_reproducible_and_prefix_stable():
    assert random_groups(6, "validation", 3) == random_groups(6, "validation", 3)
    assert random_groups(3, "validation", 3) == random_groups(6, "validation", 3)[:3]
    assert random_groups(3, "validation", 3) != random_groups(3, "validation", 4)
    assert random_groups(0, "test") == []


def test_splits_are_disjoint():
    splits = {s: random_groups(60, s, 0) for s in ("train", "validation", "test")}
    frequencies = {s: {g.omega for g in groups} for s, groups in splits.items()}
    assert all(len(f) == 60 for f in frequencies.values())
    assert not frequencies["train"] & frequencies["validation"]
    assert not frequencies["train"] & frequencies["test"]
    assert not frequencies["validation"] & frequencies["test"]


def test_generator_covers_the_documented_distribution():
    groups = random_groups(90, "train", 1)
    assert (
        {g.n for g in groups} <= set(range(3, 16)) and min(g.n for g in groups) <= 4 and max(g.n for g in groups) >= 14
    )
    assert {g.graph_kind for g in groups} == {"ring", "all", "random"}
    ratios = np.array([g.gain / locking_gain(g.omega, g.adjacency()) for g in groups])
    assert ratios.min() >= 0.1 - 1e-12 and ratios.max() <= 10 + 1e-12
    assert np.mean(ratios < 1) > 0.3 and np.mean(ratios > 1) > 0.3  # below and above locking
    durations = np.array([g.duration for g in groups])
    assert durations.min() >= 10 and durations.max() <= 300
    assert all(connected_components(g.adjacency(), directed=False)[0] == 1 for g in groups)
    assert len({g.assisted for g in groups}) > 8
    with pytest.raises(ValueError, match="split must be one of"):
        random_groups(2, "dev")


def test_locking_gain():
    assert locking_gain([1.0, 3.0], [[0, 1], [1, 0]]) == 1.0  # |ω1 − ω2| / 2
    # three in a line 0-1-2: the fastest must be carried by its single edge
    line = np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]])
    assert locking_gain([3.0, 0.0, 0.0], line) == 2.0
    assert locking_gain([1.0, 2.0, 3.0], np.zeros((3, 3))) == np.inf


def test_two_oscillators_lock_just_above_the_locking_gain():
    omega = np.array([1.0, 3.0])
    for factor, locks in ((1.05, True), (0.95, False)):
        group = SyncGroup("pair", 2, factor * locking_gain(omega, [[0, 1], [1, 0]]), tuple(omega), 0, 60.0)
        model = SyncModel.from_group(group, l2=False)
        theta = np.zeros(2)
        unwrapped = 0.0
        for _ in range(6000):
            new, _ = model.advance(theta, theta, np.zeros(()), np.zeros(()))
            unwrapped += np.angle(np.exp(1j * ((new[1] - new[0]) - (theta[1] - theta[0]))))
            theta = new
        assert (abs(unwrapped) < np.pi) == locks


def test_constant_frequency_scan_matches_the_model():
    group = random_groups(1, "test", 2)[0]
    group = dataclasses.replace(group, duration=1.5)
    got = constant_frequency_scan(group, n_frequencies=3, n_phases=2)
    # independent: each reference on its own, through SyncModel.blend / advance
    model = SyncModel.from_group(group)
    omega = np.asarray(group.omega)
    best = 0.0
    for w in np.linspace(omega.min() - 0.5, omega.max() + 0.5, 3):
        for phase0 in (0.0, np.pi):
            theta, lam, total = np.zeros(group.n), np.asarray(model.blender.lam_max), 0.0
            for k in range(151):
                ref = np.mod(phase0 + w * k * 0.01, 2 * np.pi)
                tilde, _, lam = model.blend(theta, np.asarray(ref), lam)
                total += order_parameter(tilde)
                theta, _ = model.advance(theta, tilde, np.asarray(ref), np.asarray(w))
            best = max(best, total / 151)
    assert got == pytest.approx(best, abs=1e-9)
    assert upper_bound(group, max_iter=5) >= got


def tiny_groups():
    return [dataclasses.replace(g, duration=1.0) for g in random_groups(2, "test", 0)]


def test_heldout_table_summarises_each_group():
    groups = tiny_groups()
    table = heldout_table(2, groups=groups, policies=["mean"], details=True)
    assert table["n_groups"] == 2 and table["seed"] == 0
    (row,) = table["policies"]
    assert set(row) == KEYS
    changes = [run_sync(g, ["mean"])["results"][0]["change_pct"] for g in groups]
    assert row["mean_change_pct"] == pytest.approx(np.mean(changes))
    assert row["worst_change_pct"] == pytest.approx(min(changes))
    assert row["lowered_share"] == np.mean(np.array(changes) < 0)
    for detail in table["groups"]:
        fraction = detail["results"][0]["bound_fraction"]
        gain = detail["results"][0]["r_with"] - detail["r_without"]
        assert fraction is None or fraction == pytest.approx(gain / (detail["r_bound"] - detail["r_without"]))
    with pytest.raises(ValueError, match="unknown policy 'best'"):
        heldout_table(2, policies=["best"])


def test_cli_random_json(capsys):
    assert main(["run", "sync", "--random", "2", "--max-duration", "1", "--policy", "mean", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["n_groups"] == 2 and out["seed"] == 0
    assert [p["policy"] for p in out["policies"]] == ["mean"] and set(out["policies"][0]) == KEYS
    assert main(["run", "sync", "--random", "2", "--max-duration", "1", "--policy", "mean"]) == 0
    assert "2 held-out random groups (test split, seed 0)" in capsys.readouterr().out
    assert main(["run", "sync", "--random", "2", "--group", "1"]) == 2
    assert "--group: not allowed with argument --random" in capsys.readouterr().err
    assert main(["run", "sync", "--random", "0"]) == 2
    assert "--random" in capsys.readouterr().err


def test_cli_random_on_the_validation_split_without_the_bound(capsys):
    """``--split validation --no-bound``: the validation groups' own changes, no bound fraction."""
    argv = ["run", "sync", "--random", "2", "--max-duration", "1", "--policy", "mean", "--split", "validation"]
    assert main([*argv, "--no-bound", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    (row,) = out["policies"]
    groups = [dataclasses.replace(g, duration=1.0) for g in random_groups(2, "validation", 0)]
    changes = [run_sync(g, ["mean"])["results"][0]["change_pct"] for g in groups]
    assert set(out) == {"n_groups", "seed", "policies"} and set(row) == KEYS
    assert row["mean_change_pct"] == pytest.approx(np.mean(changes), rel=1e-12)
    assert row["mean_bound_fraction"] is None
    assert main([*argv, "--no-bound"]) == 0
    assert "2 random groups (validation split, seed 0)" in capsys.readouterr().out
    assert main(["run", "sync", "--group", "1", "--split", "validation"]) == 2
    assert (
        "--split, --no-bound, --thorough-bound, --max-duration and --noise apply to --random N only"
        in capsys.readouterr().err
    )
    assert main([*argv, "--no-bound", "--thorough-bound"]) == 2
    assert "--thorough-bound: not allowed with argument --no-bound" in capsys.readouterr().err
    assert main(["run", "sync", "--random", "1", "--split", "dev"]) == 2
    assert "invalid choice: 'dev'" in capsys.readouterr().err


def test_cli_random_plot_draws_each_groups_change_against_the_bound(capsys, tmp_path):
    """``--plot`` with ``--random``: the figure is drawn after the JSON, which keeps its keys."""
    path = tmp_path / "heldout.png"
    argv = ["run", "sync", "--random", "2", "--max-duration", "1", "--policy", "mean", "--json", "--plot", str(path)]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) == {"n_groups", "seed", "policies"}
    assert path.stat().st_size > 1000 and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["run", "sync", "--random", "2", "--duration", "1"]) == 2
    assert "--random evaluates each group over its own duration" in capsys.readouterr().err
    with pytest.raises(ValueError, match="plot_heldout needs heldout_table"):
        plot_heldout({"n_groups": 2, "seed": 0, "policies": []}, str(path))


@pytest.mark.filterwarnings("ignore:motion computer .* is retired:DeprecationWarning")  # retired names on purpose
def test_thorough_bound_is_the_tighter_yardstick():
    """``--thorough-bound`` judges against ``upper_bound(thorough=True)``, never below the default bound."""
    group = dataclasses.replace(TABLE2[1], duration=3.0)
    standard = evaluate_group(group, ["guard"])
    thorough = evaluate_group(group, ["guard"], thorough=True)
    assert thorough["r_bound"] == upper_bound(group, thorough=True)
    assert thorough["r_bound"] >= standard["r_bound"] - 1e-12
    assert thorough["r_bound"] >= thorough["results"][0]["r_with"] - 1e-12  # the default policy is one of its starts
    (row,) = thorough["results"]
    assert row["bound_fraction"] == pytest.approx(
        (row["r_with"] - thorough["r_without"]) / (thorough["r_bound"] - thorough["r_without"])
    )


@pytest.mark.parametrize("domain", ["phase", "position"])
def test_cli_random_noise_json_has_todays_keys_and_each_groups_noise(capsys, domain):
    argv = ["run", "sync", "--random", "2", "--noise", "--split", "validation", "--max-duration", "1"]
    assert main([*argv, "--policy", "mean", "--no-bound", "--domain", domain, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) == {"n_groups", "seed", "policies", "domain", "noise"}
    assert out["domain"] == domain
    assert out["noise"] == [g.noise.as_dict() for g in random_groups(2, "validation", 0, noise=True)]
    assert set(out["policies"][0]) >= {"policy", "lowered_share", "mean_change_pct", "worst_change_pct"}
    assert main(["run", "sync", "--group", "1", "--noise"]) == 2
    assert "--noise apply to --random N only" in capsys.readouterr().err


def test_a_noisy_groups_row_holds_its_noise_and_the_clairvoyant_bound():
    group = dataclasses.replace(random_groups(1, "validation", 0, noise=True)[0], duration=2.0)
    row = evaluate_group(group, ["mean"])
    assert row["noise"] == group.noise.as_dict()
    assert row["r_bound"] == upper_bound(group, pace=False)
    assert row["r_bound"] >= row["results"][0]["r_with"] - 1e-9
    assert "noise" not in evaluate_group(dataclasses.replace(group, noise=None), ["mean"], bound=False)
