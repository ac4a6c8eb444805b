"""``cogblocks run amplification``: options of the library chain refused without ``--library``; a folder named."""

import pytest

from cogblocks.amplification.smoothing import STEP_LIMIT
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


def test_the_step_limit_reaches_both_directions_of_the_bundled_run(capsys, monkeypatch):
    import cogblocks.diagrams.amplification as amplification

    calls = []
    monkeypatch.setattr(amplification, "run_amplification", lambda variants, **options: calls.append(options) or {})
    assert main(["run", "amplification", "--variant", "blend", "--step-limit", "1.5", "--json"]) == 0
    assert calls == [{"step_limit": 1.5}, {"e_des": 0, "step_limit": 1.5}]
    capsys.readouterr()
    assert main(["run", "amplification", "--variant", "blend", "--json"]) == 0
    assert calls[-1] == {"e_des": 0, "step_limit": STEP_LIMIT}  # the ready diagrams' own
    capsys.readouterr()
    assert main(["run", "amplification", "--variant", "blend", "--step-limit", "NONE", "--json"]) == 0
    assert calls[-1] == {"e_des": 0, "step_limit": None}  # the deliverable's rule, unlimited


def test_the_cli_default_step_limit_is_the_ready_diagrams_default():
    import inspect

    from cogblocks.diagrams.amplification import pop_amplification, run_amplification
    from cogblocks.training.pipeline import run_pipeline

    for function in (pop_amplification, run_amplification, run_pipeline):
        assert inspect.signature(function).parameters["step_limit"].default == STEP_LIMIT == 1.0


@pytest.mark.parametrize("value", ["0", "-1", "nan", "fast"])
def test_a_step_limit_that_is_not_a_positive_factor_is_refused(capsys, value):
    assert main(["run", "amplification", "--step-limit", value]) == 2
    assert "argument --step-limit" in capsys.readouterr().err


def test_the_step_limit_reaches_the_library_chain(capsys, monkeypatch, tmp_path):
    import cogblocks.training.pipeline as pipeline

    calls = []
    monkeypatch.setattr(pipeline, "run_pipeline", lambda library, out, **options: calls.append(options) or {})
    library = tmp_path / "lib.npz"
    library.write_bytes(b"")
    for extra, expected in (([], STEP_LIMIT), (["--step-limit", "0.8"], 0.8), (["--step-limit", "none"], None)):
        argv = ["run", "amplification", "--library", str(library), "--out", str(tmp_path / "out"), "--json", *extra]
        assert main(argv) == 0
        assert calls[-1]["step_limit"] == expected
    capsys.readouterr()
