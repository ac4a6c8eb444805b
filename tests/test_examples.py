"""Every example script runs (in seconds) without error, and writes only where it is told."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parent.parent
EXAMPLES = sorted((ROOT / "examples").glob("*.py"))


def files_of(folder: Path) -> dict[Path, int]:
    return {path: path.stat().st_mtime_ns for path in folder.rglob("*") if path.is_file()}


@pytest.mark.parametrize("script", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_example_runs(script, tmp_path):
    docs = files_of(ROOT / "docs")
    result = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    assert files_of(ROOT / "docs") == docs  # by default an example writes into the working directory only
    written = [line.removeprefix("wrote ") for line in result.stdout.splitlines() if line.startswith("wrote ")]
    assert sorted(p.name for p in tmp_path.iterdir() if p.suffix == ".png") == sorted(Path(p).name for p in written)


def test_example_writes_its_figure_into_the_folder_given(tmp_path):
    folder = tmp_path / "figures"
    folder.mkdir()
    script = ROOT / "examples" / "analysis_lambda.py"
    result = subprocess.run(
        [sys.executable, str(script), str(folder)], cwd=tmp_path, capture_output=True, text=True, timeout=300
    )
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.splitlines()[-1] == f"wrote {folder / 'analysis_lambda.png'}"
    assert [p.name for p in folder.iterdir()] == ["analysis_lambda.png"]
