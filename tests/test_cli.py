"""The cogblocks command line."""

import importlib
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cogblocks.cli import main
from cogblocks.data.groups import TABLE2
from cogblocks.diagrams.sync import run_sync, sync_table


def test_help_lists_run(capsys):
    assert main([]) == 0
    assert "run" in capsys.readouterr().out


def test_sync_help_names_every_motion_computer(capsys):
    from cogblocks.diagrams.sync import MOTIONS

    assert main(["run", "sync", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    listed = text.split("motion computer(s) to run: ")[1].split(" (default")[0]
    assert listed.split(", ") == sorted(MOTIONS)


def test_console_script_help():
    out = subprocess.run([sys.executable, "-m", "cogblocks.cli", "--help"], capture_output=True, text=True, check=True)
    assert "usage: cogblocks" in out.stdout and "run" in out.stdout


def test_run_demo_json(capsys, tmp_path):
    plot = tmp_path / "demo.png"
    assert main(["run", "demo", "--duration", "20", "--json", "--plot", str(plot)]) == 0
    out, err = capsys.readouterr()
    result = json.loads(out)
    assert result["n"] == 7 and result["duration"] == 20.0
    assert 0.0 < result["r_mean"] <= 1.0
    assert plot.stat().st_size > 1000
    assert err == f"wrote {plot}\n"


def test_run_demo_bad_duration(capsys):
    assert main(["run", "demo", "--duration", "0.015"]) == 2
    assert "not a whole number of base steps" in capsys.readouterr().err


def test_run_without_target_shows_usage(capsys):
    assert main(["run"]) == 2
    assert "TARGET" in capsys.readouterr().out


# --- options are checked before any simulation, and every error names its option -----------------------------


@pytest.mark.parametrize(
    ("argv", "option", "reason"),
    [
        (["sync", "--seed", "-1"], "--seed", "expected an integer >= 0, got -1"),
        (["phase3d", "--seed", "one"], "--seed", "expected an integer >= 0, got 'one'"),
        (["phase3d", "--trajectories", "0"], "--trajectories", "expected an integer >= 1, got 0"),
        (["phase3d", "--set", "hardest"], "--set", "invalid choice: 'hardest'"),
        (["demo", "--duration", "0"], "--duration", "expected a duration > 0 s, got 0"),
        (["demo", "--duration", "nan"], "--duration", "expected a duration > 0 s"),
        (["sync", "--duration", "-10"], "--duration", "expected a duration > 0 s"),
        (["sync", "--duration", "2.005"], "--duration", "not a whole number of base steps (10 ms)"),
        (["sync", "--policy", "mean", "--policy", "best"], "--policy", "unknown motion computer 'best'"),
        (["demo", "--plot", "{tmp}/missing/figure.png"], "--plot", "no folder"),
        (["amplification", "--plot", "{tmp}/figure.docx"], "--plot", "give a file name ending in one of"),
        (["sync", "--plot", "{tmp}/figure"], "--plot", ".png"),
        (["demo", "--plot", "{tmp}/folder.png"], "--plot", "cannot write a file there"),
        (["demo", "--plot", "{tmp}/" + "x" * 300 + ".png"], "--plot", "File name too long"),
    ],
)
def test_bad_options_are_refused_before_any_run(capsys, tmp_path, argv, option, reason):
    (tmp_path / "folder.png").mkdir()
    argv = [arg.format(tmp=tmp_path) for arg in argv]
    assert main(["run", *argv]) == 2
    out, err = capsys.readouterr()
    assert out == ""  # nothing ran
    assert f"argument {option}" in err and reason in err


@pytest.mark.parametrize(
    ("argv", "option", "reason"),
    [
        (["live", "sync", "--in", "a", "--out", "b", "--duration", "-1"], "--duration", "expected a duration > 0 s"),
        (["live", "phase", "--in", "a", "--out", "b", "--duration", "1", "--timeout", "x"], "--timeout", "got 'x'"),
        (["live", "sync", "--in", "a", "--out", "b", "--duration", "1", "--policy", "best"], "--policy", "'best'"),
        (["sweep", "sync", "--workers", "0"], "--workers", "expected an integer >= 1, got 0"),
        (["sweep", "sync", "--random", "-2"], "--random", "expected an integer >= 1, got -2"),
        (["sweep", "sync", "--group-seed", "-1"], "--group-seed", "expected an integer >= 0, got -1"),
        (["sweep", "sync", "--seeds", "two"], "--seeds", "expected an integer >= 1, got 'two'"),
    ],
)
def test_live_and_sweep_options_are_refused_before_any_run(capsys, argv, option, reason):
    assert main(argv) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert f"argument {option}" in err and reason in err


def test_a_failed_plot_keeps_the_printed_results(capsys, tmp_path):
    """The figure is drawn after the results are printed: a file system error loses nothing, not even the figure."""
    plot = tmp_path / "figure.png"  # valid folder and format, but a link to a folder removed since
    plot.symlink_to(tmp_path / "removed" / "figure.png")
    assert main(["run", "demo", "--duration", "20", "--plot", str(plot)]) == 2
    out, err = capsys.readouterr()
    assert out.startswith("Kuramoto group of 7 (ring, gain 0.6286) over 20.0 s: time-averaged order parameter ")
    assert "cogblocks: error:" in err and "No such file or directory" in err and f"wrote {plot}" not in err
    spare = Path(re.search(r"saved in (\S+\.png) instead", err).group(1))
    assert spare.read_bytes().startswith(b"\x89PNG")  # the figure is in the temporary file
    spare.unlink()


# --- run sync ---------------------------------------------------------------------------------------------------


def kuramoto_r_mean(group, n_steps: int) -> float:
    """Time-averaged order parameter of a ring Kuramoto group without L2, forward Euler at 10 ms."""
    omega, n = np.array(group.omega), group.n
    ring = np.roll(np.eye(n), 1, axis=1) + np.roll(np.eye(n), -1, axis=1)
    theta, r = np.zeros(n), []
    for _ in range(n_steps):
        r.append(abs(np.exp(1j * theta).mean()))
        theta = np.mod(
            theta + 0.01 * (omega + group.gain * (ring * np.sin(theta[None, :] - theta[:, None])).sum(1)), 2 * np.pi
        )
    return float(np.mean(r))


def test_run_sync_duration_seed_and_plot(capsys, tmp_path):
    plot = tmp_path / "sync.svg"
    common = ["run", "sync", "--group", "1", "--policy", "mean", "--duration", "2.5", "--json"]
    assert main([*common, "--plot", str(plot)]) == 0
    out, err = capsys.readouterr()
    result = json.loads(out)  # one JSON object, nothing else on stdout
    assert result["r_without"] == pytest.approx(kuramoto_r_mean(TABLE2[1], 251), abs=1e-12)  # t = 0 … 2.5 s
    assert [row["policy"] for row in result["results"]] == ["mean"]
    assert err == f"wrote {plot}\n" and plot.read_text().startswith("<?xml")
    position = {}
    for seed in (None, "0", "7"):
        extra = [] if seed is None else ["--seed", seed]
        assert main([*common, "--domain", "position", *extra]) == 0
        position[seed] = json.loads(capsys.readouterr().out)
    assert position[None] == position["0"]  # 0 is the default seed of the sensor noise
    assert position["7"]["results"][0]["r_with"] != position["0"]["results"][0]["r_with"]
    assert position["7"]["r_without"] == position["0"]["r_without"] == result["r_without"]  # no sensing without L2


def test_no_handover_runs_the_position_domain_as_pop_sync_handover_false(capsys):
    common = ["run", "sync", "--group", "1", "--policy", "mean", "--duration", "5", "--domain", "position", "--json"]
    rows = {}
    for extra in ([], ["--no-handover"]):
        assert main([*common, *extra]) == 0
        rows[bool(extra)] = json.loads(capsys.readouterr().out)["results"][0]
    expected = run_sync(1, ["mean"], "position", duration=5.0, progress=False, handover=False)["results"][0]
    assert rows[True] == expected
    assert rows[False]["r_with"] != expected["r_with"]  # the avatar showed the person for the first seconds
    assert main(["run", "sync", "--group", "1", "--policy", "mean", "--no-handover"]) == 2
    assert "--no-handover applies to --domain position only" in capsys.readouterr().err


def test_run_sync_prints_each_line_as_soon_as_it_is_known():
    """Text output to a pipe is not held back until the end: kill the run after its first line."""
    command = [sys.executable, "-m", "cogblocks.cli", "run", "sync", "--group", "1", "--policy", "lookahead"]
    with subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True) as process:
        first = process.stdout.readline()
        process.kill()  # the look-ahead run (seconds) is still going
        rest = process.stdout.read()
    assert first.startswith("Group 1: time-averaged order parameter without L2 0.7615")
    assert "with L2" not in rest


def test_progress_bars_are_named_after_their_run(capsys):
    head, row = sync_table(1, ["mean"], duration=10.5, progress=True)
    err = capsys.readouterr().err
    assert "group 1, without L2" in err and "group 1, L2 with mean" in err
    # the bar splits the run into chunks; the result is the same, tick for tick
    assert run_sync(1, ["mean"], duration=10.5, progress=False) == {**head, "results": [row]}


# --- training commands never overwrite the shipped weights by default -------------------------------------------


@pytest.mark.parametrize("name", ["encoder", "corrector"])
def test_training_writes_to_the_working_directory_by_default(name, tmp_path, monkeypatch):
    module = importlib.import_module(f"cogblocks.training.{name}")
    monkeypatch.chdir(tmp_path)
    out = module._parser().parse_args([]).out
    assert out.resolve() == tmp_path / f"{name}.pt"
    assert module.SHIPPED.is_file() and module.SHIPPED.resolve() != out.resolve()
    assert module._parser().parse_args(["--out", str(module.SHIPPED)]).out == module.SHIPPED  # only when asked


def test_sync_dqn_training_needs_out(capsys):
    from cogblocks.training.sync_dqn import _parser

    with pytest.raises(SystemExit):
        _parser().parse_args(["--seed", "0"])
    assert "the following arguments are required: --out" in capsys.readouterr().err
