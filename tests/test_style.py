"""The tree keeps the project's style: ``ruff check`` and ``ruff format --check`` pass (settings in pyproject)."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _ruff(*args: str) -> subprocess.CompletedProcess:
    exe = shutil.which("ruff")
    cmd = [exe] if exe else [sys.executable, "-m", "ruff"]
    return subprocess.run(
        [*cmd, *args, "cogblocks", "tests", "benchmarks", "examples"], cwd=ROOT, capture_output=True, text=True
    )


@pytest.mark.parametrize("args", [("check",), ("format", "--check")], ids=["lint", "format"])
def test_ruff_passes(args):
    result = _ruff(*args)
    assert result.returncode == 0, result.stdout + result.stderr
