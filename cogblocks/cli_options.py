"""Option values of the ``cogblocks`` command, checked by argparse so that every error names its option.

Output files are checked before any compute (:func:`check_output`, or :func:`output_type` as an
argparse ``type``): the folder exists and can be written (a file is created and removed there,
which also catches read-only mounts and ``/proc``), the name is not a folder, and the suffix is one
the writer knows. If a write still fails at the end (the disk filled, the folder went away),
:func:`write_safely` writes the same data to a temporary file and says where.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from cogblocks.sim.timing import BASE_STEP

__all__ = [
    "WrittenElsewhere",
    "check_output",
    "check_output_folder",
    "output_folder_type",
    "output_type",
    "plot_output",
    "print_result",
    "write_output",
    "write_safely",
    "COUNT",
    "DURATION",
    "OUTPUT_FOLDER",
    "PLOT_PATH",
    "POLICY",
    "PORT",
    "SEED",
    "STEP",
    "TRACE_PATH",
]


def _option(convert: Callable[[str], Any]) -> Callable[[str], Any]:
    """An argparse ``type``: ``convert(text)``, its ValueError shown by argparse with the option's name."""

    def parse(text: str) -> Any:
        try:
            return convert(text)
        except ValueError as error:
            raise argparse.ArgumentTypeError(str(error)) from None

    return parse


def _integer(minimum: int) -> Callable[[str], int]:
    def convert(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise ValueError(f"expected an integer >= {minimum}, got {text!r}") from None
        if value < minimum:
            raise ValueError(f"expected an integer >= {minimum}, got {value}")
        return value

    return convert


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"expected a number of seconds, got {text!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise ValueError(f"expected a duration > 0 s, got {text}")
    return value


def _duration(text: str) -> float:
    value = _seconds(text)
    steps = value / BASE_STEP
    if not math.isclose(steps, round(steps), rel_tol=0.0, abs_tol=1e-6):
        raise ValueError(f"{text} s is not a whole number of base steps ({BASE_STEP * 1000:g} ms)")
    return value


def _port(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = -1
    if not 0 <= value <= 65535:  # 0: a free port the system chooses
        raise ValueError(f"expected a TCP port, 0-65535 (0: any free port), got {text!r}")
    return value


def _policy(text: str) -> str:
    from cogblocks.diagrams.sync import MOTIONS

    if text not in MOTIONS:
        raise ValueError(f"unknown motion computer {text!r} (choose from {', '.join(sorted(MOTIONS))})")
    return text


class WrittenElsewhere(OSError):
    """A write failed and the data went to a temporary file instead; the message names both."""

    def __init__(self, message: str, path: Path) -> None:
        super().__init__(message)
        self.path = path


def _writable(folder: Path) -> str | None:
    """Why no file can be created in ``folder``, or None; tried for real (permissions alone can lie)."""
    try:
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".cogblocks-check-")
    except OSError as error:
        return f"cannot write a file in {str(folder)!r} ({error.strerror or error})"
    os.close(fd)
    os.unlink(probe)
    return None


def _problem(text: str, suffixes: Iterable[str] | None) -> str | None:
    path = Path(text)
    if suffixes is not None:
        known = sorted({s.lower() for s in suffixes})
        if path.suffix.lower() not in known:
            return (
                f"{text!r}: give a file name ending in one of {', '.join(known)} (got {path.suffix or 'no suffix'!r})"
            )
    folder = path.parent
    try:
        if not folder.is_dir():
            return f"{text!r}: no folder {str(folder)!r}"
        if path.is_dir():
            return f"{text!r} is a folder: cannot write a file there"
    except OSError as error:  # e.g. a name too long for the file system
        return f"{text!r}: cannot write a file there ({error.strerror})"
    problem = _writable(folder)
    return None if problem is None else f"{text!r}: {problem}"


def check_output(path: str | os.PathLike[str], suffixes: Iterable[str] | None, option: str = "--save") -> str:
    """Check, before any compute, that ``path`` can be written as an output of ``option``.

    Parameters
    ----------
    path : str or path-like
        The output file.
    suffixes : iterable of str, or None
        Known suffixes with their dot (``(".npz", ".parquet")``), matched case-insensitively;
        ``None`` accepts any.
    option : str
        The option's name, for the message.

    Returns
    -------
    str
        ``path``, as given.

    Raises
    ------
    ValueError
        Naming the option, the path and what is wrong: no such folder, a folder that cannot be
        written, a folder given as the file, an unknown suffix.
    """
    problem = _problem(os.fspath(path), suffixes)
    if problem is not None:
        raise ValueError(f"{option}: {problem}")
    return os.fspath(path)


def _folder_problem(text: str) -> str | None:
    folder = Path(text)
    if folder.exists() and not folder.is_dir():
        return f"{text!r} is a file, not a folder"
    target = folder if folder.is_dir() else folder.parent
    if not target.is_dir():
        return f"{text!r}: no folder {str(target)!r}"
    problem = _writable(target)
    return None if problem is None else f"{text!r}: {problem}"


def check_output_folder(path: str | os.PathLike[str], option: str = "--out") -> str:
    """Check that ``path`` is a writable folder, or can be made one (its parent exists and can be written).

    Raises
    ------
    ValueError
        Naming the option, the path and what is wrong.
    """
    problem = _folder_problem(os.fspath(path))
    if problem is not None:
        raise ValueError(f"{option}: {problem}")
    return os.fspath(path)


def output_folder_type(text: str) -> str:
    """An argparse ``type`` checking an output folder as :func:`check_output_folder` does."""
    problem = _folder_problem(text)
    if problem is not None:
        raise argparse.ArgumentTypeError(problem)
    return text


def output_type(suffixes: Iterable[str] | None) -> Callable[[str], str]:
    """An argparse ``type`` checking an output file as :func:`check_output` does (argparse names the option)."""
    known = None if suffixes is None else tuple(suffixes)

    def parse(text: str) -> str:
        problem = _problem(text, known)
        if problem is not None:
            raise argparse.ArgumentTypeError(problem)
        return text

    return parse


def write_safely(path: str | os.PathLike[str], writer: Callable[[str], Any], what: str = "the output") -> Path:
    """Call ``writer(path)``; if that fails, write the same data to a temporary file and raise saying where.

    Parameters
    ----------
    path : str or path-like
        Where the data should go.
    writer : callable
        Writes the data to the path it is given (the temporary file keeps ``path``'s suffix, so
        writers that choose the format by suffix write the same format).
    what : str
        What the data is, for the message.

    Returns
    -------
    Path
        ``path``, once written.

    Raises
    ------
    WrittenElsewhere
        An ``OSError`` whose message names ``path``, why it failed and the temporary file that
        holds the data. If the temporary file cannot be written either, the original error.
    """
    try:
        writer(os.fspath(path))
        return Path(path)
    except OSError as error:
        fd, spare = tempfile.mkstemp(prefix=f"cogblocks-{Path(path).stem}-", suffix=Path(path).suffix)
        os.close(fd)
        try:
            writer(spare)
        except OSError:
            os.unlink(spare)
            raise error from None
        message = (
            f"could not write {what} to {os.fspath(path)!r} ({error.strerror or error}); it is saved in {spare} instead"
        )
        raise WrittenElsewhere(message, Path(spare)) from error


def print_result(result: dict[str, Any], as_json: bool, render: Callable[[dict[str, Any]], str]) -> None:
    """Print ``result`` as one JSON object or as ``render``'s text, flushed so that a pipe sees it at once."""
    print(json.dumps(result) if as_json else render(result), flush=True)


def plot_output(path: str | None, draw: Callable[[str], Any]) -> None:
    """Draw a figure to ``path`` (after the results are printed, so a failure loses none) and say so."""
    if path:
        write_output(path, draw, "the figure")


def write_output(path: str, writer: Callable[[str], Any], what: str) -> None:
    """Write an output the options checked (:func:`write_safely`: if it still fails, a temporary file keeps it)."""
    write_safely(path, writer, what)
    print(f"wrote {path}", file=sys.stderr, flush=True)


def _plot_path(text: str) -> str:
    """A figure file that can be written: an existing, writable folder and a format matplotlib saves."""
    from matplotlib.backend_bases import FigureCanvasBase

    formats = FigureCanvasBase.get_supported_filetypes()
    return output_type([f".{name}" for name in formats])(text)


SEED = _option(_integer(0))  # numpy's generators take seeds >= 0
COUNT = _option(_integer(1))
DURATION = _option(_duration)
STEP = _option(_seconds)
POLICY = _option(_policy)
PORT = _option(_port)
PLOT_PATH = _plot_path
TRACE_PATH = output_type((".npz", ".parquet"))  # what Trace.save writes
OUTPUT_FOLDER = output_folder_type
