"""Ctrl-C and SIGTERM stop a long ``cogblocks run sync`` cleanly: the figures so far, one line, 130 or 143,
no traceback, no worker process left running."""

import json
import os
import signal
import subprocess
import sys
import time

import psutil
import pytest

TIMEOUT = 120  # seconds for any wait; the process is killed past it


def _interrupt(argv, sig, ready):
    """Start the command, wait until ``ready(stdout_line)`` or its workers exist, send ``sig``, collect."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    process = subprocess.Popen(
        [sys.executable, "-m", "cogblocks.cli", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        first = ready(process)
        children = psutil.Process(process.pid).children(recursive=True)
        process.send_signal(sig)
        out, err = process.communicate(timeout=TIMEOUT)
    except BaseException:
        process.kill()
        process.communicate()
        raise
    return first, out, err, process.returncode, children


def _first_line(process):
    return process.stdout.readline()


def _workers_started(n):
    def ready(process):
        deadline = time.monotonic() + TIMEOUT
        while time.monotonic() < deadline:
            workers = psutil.Process(process.pid).children(recursive=True)
            if sum("python" in w.name() for w in workers) >= n:
                time.sleep(1.0)  # let them take up their groups
                return ""
            time.sleep(0.2)
        raise TimeoutError("no workers started")

    return ready


def _gone(children):
    _, alive = psutil.wait_procs(children, timeout=30)
    for leftover in alive:
        leftover.kill()
    return alive


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_run_sync_group_stops_with_the_figures_it_has(sig, code):
    first, out, err, returncode, _ = _interrupt(["run", "sync", "--group", "3"], sig, _first_line)
    assert first.startswith("Group 3: time-averaged order parameter without L2 ")
    assert returncode == code
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    assert "cogblocks: interrupted" in err and "figures above" in err


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_run_sync_random_with_workers_leaves_no_worker_behind(sig, code):
    argv = ["run", "sync", "--random", "4", "--workers", "2", "--policy", "mean", "--no-bound"]
    _, out, err, returncode, children = _interrupt(argv, sig, _workers_started(2))
    assert children, "the test needs the workers to have started"
    assert returncode == code
    assert "Traceback" not in err and "cogblocks: interrupted" in err
    assert _gone(children) == []  # every worker ended


def test_run_sync_json_interrupted_prints_the_figures_known_so_far(capsys, monkeypatch):
    """Ctrl-C arriving after the first figure (injected into the real run) still prints that figure as JSON."""
    from cogblocks.cli import main
    from cogblocks.diagrams import sync

    real = sync.sync_table

    def interrupted_after_the_first_figure(*args, **kwargs):
        rows = real(*args, **kwargs)
        yield next(rows)
        raise KeyboardInterrupt

    monkeypatch.setattr(sync, "sync_table", interrupted_after_the_first_figure)
    assert main(["run", "sync", "--group", "1", "--policy", "mean", "--duration", "1", "--json"]) == 130
    out, err = capsys.readouterr()
    result = json.loads(out)
    assert result["interrupted"] is True and result["results"] == [] and 0 < result["r_without"] <= 1
    assert "cogblocks: interrupted by Ctrl-C" in err


def test_run_sync_random_reports_each_group_and_keeps_them_on_ctrl_c():
    """Each finished group reaches stderr at once; a real SIGINT then prints the table of the groups done."""
    argv = ["run", "sync", "--random", "40", "--policy", "mean", "--no-bound", "--max-duration", "5", "--json"]

    def first_group(process):
        return process.stderr.readline()

    first, out, err, returncode, _ = _interrupt(argv, signal.SIGINT, first_group)
    assert first.startswith("group 1/40 done: ") and "r without L2 " in first, first
    assert returncode == 130
    assert "Traceback" not in err and "cogblocks: interrupted by Ctrl-C" in err
    lines = [first, *(line for line in err.splitlines() if line.startswith("group "))]
    changes = [float(line.rsplit("mean ", 1)[1].split(" %")[0]) for line in lines]
    table = json.loads(out)
    assert table["interrupted"] is True and table["n_requested"] == 40
    assert table["n_groups"] == len(lines) == len(table["groups_done"]) < 40
    (mean,) = table["policies"]
    assert abs(mean["mean_change_pct"] - sum(changes) / len(changes)) < 0.01  # the lines print 2 decimals


# Sends a real SIGINT to the process the first time ``MODULE`` is imported, then runs the command.
_SIGINT_ON_IMPORT = """
import importlib.abc, os, runpy, signal, sys

class SigintOnImport(importlib.abc.MetaPathFinder):
    module = sys.argv[1]

    def find_spec(self, name, path=None, target=None):
        if name == self.module:
            sys.meta_path.remove(self)
            os.kill(os.getpid(), signal.SIGINT)
        return None

sys.meta_path.insert(0, SigintOnImport())
sys.argv = ["cogblocks", *sys.argv[2:]]
runpy.run_module("cogblocks.cli", run_name="__main__", alter_sys=True)
"""


@pytest.mark.parametrize("module", ["numpy", "matplotlib", "cogblocks.experiments.amplification_cli"])
def test_ctrl_c_while_the_command_loads_prints_one_line(module, tmp_path):
    """numpy loads with the engine, matplotlib while --plot is parsed, the amplification CLI with the parser."""
    plot = str(tmp_path / "figure.png")
    argv = [sys.executable, "-c", _SIGINT_ON_IMPORT, module, "run", "sync", "--group", "3", "--plot", plot]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=TIMEOUT)  # without the fix: a run of minutes
    assert done.returncode == 130, done.stderr
    assert done.stderr == "cogblocks: interrupted by Ctrl-C before the command started\n"
    assert done.stdout == "" and not (tmp_path / "figure.png").exists()
