"""Every output path of the command is checked before any compute; a write that still fails loses nothing."""

from pathlib import Path

import numpy as np
import pytest

from cogblocks.cli import main
from cogblocks.cli_options import WrittenElsewhere, check_output, check_output_folder, write_safely

LIVE = ["live", "phase", "--in", "arm", "--out", "phase", "--duration", "1", "--timeout", "0.1"]


@pytest.mark.parametrize(
    ("argv", "option", "reason"),
    [
        ([*LIVE, "--save", "/nonexistent/x.npz"], "--save", "no folder '/nonexistent'"),
        ([*LIVE, "--save", "{tmp}/x.csv"], "--save", "ending in one of .npz"),
        (
            ["run", "sync", "--group", "1", "--policy", "mean", "--save-trace", "/nonexistent/t.npz"],
            "--save-trace",
            "no folder",
        ),
        (
            ["run", "sync", "--group", "1", "--policy", "mean", "--save-trace", "{tmp}/t.txt"],
            "--save-trace",
            "ending in one of .npz, .parquet",
        ),
        (["run", "demo", "--save-trace", "/nonexistent/t.txt"], "--save-trace", "ending in one of"),
        (["run", "demo", "--plot", "/proc/fig.png"], "--plot", "cannot write a file in '/proc'"),
        (["run", "sync", "--group", "1", "--plot", "/proc/fig.png"], "--plot", "cannot write a file in '/proc'"),
        (["sweep", "sync", "--groups", "1", "--out", "/nonexistent/r.csv"], "--out", "no folder"),
        (["sweep", "sync", "--groups", "1", "--out", "{tmp}/r.xlsx"], "--out", "ending in one of .csv, .parquet"),
        (["run", "amplification", "--library", "{tmp}/lib.npz", "--out", "/nonexistent/a/b"], "--out", "no folder"),
        (["run", "amplification", "--library", "{tmp}/lib.npz", "--out", "/proc/a"], "--out", "cannot write"),
        (["run", "amplification", "--library", "{tmp}/lib.npz", "--out", "{tmp}/file"], "--out", "is a file"),
    ],
)
def test_every_output_path_is_refused_before_any_compute(capsys, tmp_path, argv, option, reason):
    (tmp_path / "file").write_text("")
    (tmp_path / "lib.npz").write_bytes(b"")  # a library file exists: the output folder is what is refused
    assert main([arg.format(tmp=tmp_path) for arg in argv]) == 2
    out, err = capsys.readouterr()
    assert out == ""  # nothing ran
    assert f"argument {option}" in err and reason in err, err


def test_check_output_names_the_option_and_accepts_a_good_path(tmp_path):
    assert check_output(tmp_path / "x.NPZ", (".npz",), "--record") == str(tmp_path / "x.NPZ")
    with pytest.raises(ValueError, match=r"^--record: .*x.csv.*ending in one of .npz"):
        check_output(tmp_path / "x.csv", (".npz",), "--record")
    with pytest.raises(ValueError, match=r"^--scope: .*no folder"):
        check_output(tmp_path / "missing" / "x.npz", None, "--scope")
    assert check_output_folder(tmp_path / "new", "--out") == str(tmp_path / "new")
    assert not (tmp_path / "new").exists()  # checking makes nothing
    assert list(tmp_path.iterdir()) == []  # and leaves no probe file behind


def test_a_write_that_fails_at_the_end_goes_to_a_temporary_file(tmp_path):
    data = np.arange(5.0)
    target = tmp_path / "gone" / "x.npz"  # the folder vanished during the run
    with pytest.raises(WrittenElsewhere) as caught:
        write_safely(target, lambda path: np.savez(path, data=data), "the trace")
    spare = caught.value.path
    try:
        assert str(target) in str(caught.value) and str(spare) in str(caught.value)
        assert "the trace" in str(caught.value) and spare.suffix == ".npz"
        with np.load(spare) as stored:
            np.testing.assert_array_equal(stored["data"], data)
    finally:
        spare.unlink()
    assert write_safely(tmp_path / "y.npz", lambda path: np.savez(path, data=data)) == tmp_path / "y.npz"
    assert Path(tmp_path / "y.npz").is_file()


# --- every command, every output option ------------------------------------------------------------------------

#: The shortest command line of every command; ``{file}`` is an existing input file.
_LIVE = ["--in", "a", "--out", "b", "--duration", "1"]
BASE = {
    "run sync": ["run", "sync"],
    "run phase3d": ["run", "phase3d"],
    "run phase1d": ["run", "phase1d"],
    "run amplification": ["run", "amplification", "--library", "{file}"],
    "run demo": ["run", "demo"],
    "sweep sync": ["sweep", "sync", "--groups", "1"],
    "analyse group": ["analyse", "group", "{file}", "--markers", "A,B"],
    **{f"live {name}": ["live", name, *_LIVE] for name in ("phase", "sync", "l1")},
    **{f"replay {name}": ["replay", "{file}", name] for name in ("phase", "sync", "l1")},
    "view": ["view", "{file}"],
}
#: Options that name files the command writes, and a suffix each accepts.
OUTPUTS = {"--save": ".npz", "--save-trace": ".npz", "--plot": ".png", "--record": ".xdf", "--out": ".csv"}
#: Options that name files the command reads.
INPUTS = {"--library", "--recording"}


def _commands():
    """Every leaf command of the parser with its options."""
    import argparse

    from cogblocks.cli import _build_parser

    def walk(parser, words):
        subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if not subs:
            yield " ".join(words), parser
        for action in subs:
            for name, sub in action.choices.items():
                yield from walk(sub, [*words, name])

    return dict(walk(_build_parser(), []))


def test_every_command_is_in_the_output_check():
    assert set(_commands()) == set(BASE)


@pytest.mark.parametrize("command", sorted(BASE))
def test_every_output_option_of_every_command_is_checked_before_any_compute(capsys, tmp_path, command):
    (tmp_path / "input.npz").write_bytes(b"PK")
    base = [word.format(file=tmp_path / "input.npz") for word in BASE[command]]
    files = [a for a in _commands()[command]._actions if a.option_strings and a.metavar in ("FILE", "DIR")]
    assert {a.option_strings[0] for a in files} <= set(OUTPUTS) | INPUTS, "a new file option: OUTPUTS or INPUTS?"
    for action in files:
        option = action.option_strings[0]
        if option in INPUTS:
            continue
        suffix = "" if action.metavar == "DIR" else OUTPUTS[option]
        assert main([*base, option, f"/nonexistent-cogblocks/x{suffix}"]) == 2, (command, option)
        out, err = capsys.readouterr()
        assert out == "" and f"argument {option}" in err and "no folder" in err, (command, option, err)


@pytest.mark.parametrize("argv", [[*LIVE, "--scope", "70000"], ["view", "x.npz", "--port", "-1"]])
def test_a_port_out_of_range_is_refused_before_any_compute(capsys, argv):
    assert main(argv) == 2
    assert "expected a TCP port, 0-65535" in capsys.readouterr().err
