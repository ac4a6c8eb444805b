"""The cogblocks command line."""

import json
import subprocess
import sys

from cogblocks.cli import main


def test_help_lists_run(capsys):
    assert main([]) == 0
    assert "run" in capsys.readouterr().out


def test_console_script_help():
    out = subprocess.run([sys.executable, "-m", "cogblocks.cli", "--help"], capture_output=True, text=True, check=True)
    assert "usage: cogblocks" in out.stdout and "run" in out.stdout


def test_run_demo_json(capsys, tmp_path):
    plot = tmp_path / "demo.png"
    assert main(["run", "demo", "--duration", "20", "--json", "--plot", str(plot)]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["n"] == 7 and result["duration"] == 20.0
    assert 0.0 < result["r_mean"] <= 1.0
    assert plot.stat().st_size > 1000


def test_run_demo_bad_duration(capsys):
    assert main(["run", "demo", "--duration", "0.015"]) == 2
    assert "not a whole number of base steps" in capsys.readouterr().err


def test_run_without_target_shows_usage(capsys):
    assert main(["run"]) == 2
    assert "TARGET" in capsys.readouterr().out
