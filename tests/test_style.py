"""The tree keeps the project's style: ``ruff check`` and ``ruff format --check`` pass (settings in pyproject)."""

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PATHS = ("cogblocks", "tests", "benchmarks", "examples", "studies")


def _ruff(*args: str) -> subprocess.CompletedProcess:
    exe = shutil.which("ruff")
    cmd = [exe] if exe else [sys.executable, "-m", "ruff"]
    return subprocess.run(
        [*cmd, *args, "cogblocks", "tests", "benchmarks", "examples", "studies"],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )


@pytest.mark.parametrize("args", [("check",), ("format", "--check")], ids=["lint", "format"])
def test_ruff_passes(args):
    result = _ruff(*args)
    assert result.returncode == 0, result.stdout + result.stderr


#: Comments and docstrings say why, never when: history belongs in the changelog.
HISTORY = re.compile(
    r"\b(first|second|third|fourth|fifth|sixth|seventh|eighth|ninth|tenth|eleventh|twelfth|thirteenth|fourteenth"
    r"|fifteenth|\d+(st|nd|rd|th)) round\b|\bround \d+\b|\bsessions? \d+\b|\bsession-\d+\b|\bthis session\b"
    r"|\bin (a|an|the) (earlier|previous|last) session\b|\bcommit [0-9a-f]{7,40}\b|\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*\d)"
    r"[0-9a-f]{12,40}\b",
    re.IGNORECASE,
)

#: Modules whose history text is still to be moved to the changelog (none left).
HISTORY_PENDING: set[str] = set()


def history_lines(text: str) -> list[int]:
    """Lines of ``text`` whose comments or strings narrate history (numbered rounds, sessions, commit hashes)."""
    return [n for n, line in enumerate(text.splitlines(), 1) if HISTORY.search(line)]


def test_comments_and_docstrings_say_why_never_when():
    found = [
        f"{path.relative_to(ROOT)}:{n}"
        for path in sorted((ROOT / "cogblocks").rglob("*.py"))
        if str(path.relative_to(ROOT)) not in HISTORY_PENDING
        for n in history_lines(path.read_text())
    ]
    assert not found, "history in code (say why, not when; history goes in the changelog):\n" + "\n".join(found)


@pytest.mark.parametrize(
    "line",
    [
        "# chosen in the thirteenth round",
        '"""Since the 9th round the plan is emitted."""',
        "# as in session 12",
        "# the session-10 guard start",
        "# fixed by commit 3f9c2ab",
        "# see 5c5fe2a1b9d0e4f7a8c3",
    ],
)
def test_the_history_check_finds_narration(line):
    assert history_lines(line) == [1]


@pytest.mark.parametrize("line", ["x = round(y, 3)", "# rounds of training", "# a session id of LSL", "seed=0"])
def test_the_history_check_leaves_ordinary_words_alone(line):
    assert history_lines(line) == []
