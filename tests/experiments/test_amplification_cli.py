"""``cogblocks run amplification``: options of the library chain refused without ``--library``; a folder named."""

import pytest

from cogblocks.cli import main
from cogblocks.training.pipeline import load_library


@pytest.mark.parametrize(
    ("argv", "named"),
    [
        (["--out", "{tmp}"], "--out"),
        (["--quick"], "--quick"),
        (["--seed", "3", "--dt", "0.02"], "--seed, --dt"),
        (["--label-field", "afraid", "--json"], "--label-field"),
    ],
)
def test_library_options_without_a_library_are_refused_naming_them(capsys, tmp_path, argv, named):
    assert main(["run", "amplification", *[a.format(tmp=tmp_path) for a in argv]]) == 2
    out, err = capsys.readouterr()
    assert out == ""  # refused before the bundled run
    assert f"{named} appl" in err and "--library FILE only" in err


def test_a_folder_given_as_a_library_is_called_a_folder(capsys, tmp_path):
    assert main(["run", "amplification", "--library", str(tmp_path), "--out", str(tmp_path / "out")]) == 2
    assert "argument --library" in (err := capsys.readouterr().err) and "is a folder" in err
    with pytest.raises(ValueError, match=r"is a folder: give a library file"):
        load_library(tmp_path)
