"""Reading the project's own files (snapshots, traces, diagrams, weights, caches): every failure names the file
and what is wrong with it, as a :class:`FileFormatError`, and never advises loading it unsafely."""

from __future__ import annotations

import errno
import json
import os
import zipfile
import zlib
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["FileFormatError", "existing_file", "load_torch", "open_npz", "parse_json"]


class FileFormatError(ValueError):
    """A file exists but is not what it should be: empty, truncated, garbage or of another kind."""


def _why(error: BaseException) -> str:
    """The reader's complaint, without its advice to load pickled data (that can run arbitrary code)."""
    text = str(error) or type(error).__name__
    if "pickle" in text.lower() or "weights_only" in text:
        return "it holds pickled Python objects, which are never loaded: loading them can run arbitrary code"
    return text.splitlines()[0]


def existing_file(path: str | os.PathLike[str], what: str) -> Path:
    """``path`` as a Path after checking that it is a file that is not empty; errors name the file."""
    file = Path(path)
    if file.is_dir():
        raise IsADirectoryError(errno.EISDIR, f"is a folder, expected a {what} file", str(file))
    if not file.is_file():
        raise FileNotFoundError(errno.ENOENT, f"no such {what} file", str(file))
    if file.stat().st_size == 0:
        raise FileFormatError(f"{file}: empty file, expected a {what}")
    return file


@contextmanager
def open_npz(path: str | os.PathLike[str], what: str) -> Iterator[Any]:
    """Open a NumPy ``.npz`` archive without pickles; damage found while reading it names the file too.

    Raises
    ------
    FileFormatError
        The file is empty, not an ``.npz`` archive (garbage, a single ``.npy`` array), truncated,
        holds pickled objects, or lacks an array the reader asks for.
    """
    file = existing_file(path, what)
    try:
        archive = np.load(file, allow_pickle=False)
    except (OSError, EOFError, ValueError, zipfile.BadZipFile) as error:
        raise FileFormatError(f"{file}: not a readable {what} (a NumPy .npz archive): {_why(error)}") from None
    if not isinstance(archive, np.lib.npyio.NpzFile):
        raise FileFormatError(f"{file}: a single NumPy array, not the .npz archive of a {what}")
    with archive:
        try:
            yield archive
        except (zipfile.BadZipFile, zlib.error, EOFError, OSError) as error:
            raise FileFormatError(f"{file}: the {what} is damaged (truncated?): {_why(error)}") from None
        except KeyError as error:
            raise FileFormatError(f"{file}: not a {what}: no array {error}") from None
        except ValueError as error:
            if "pickle" not in str(error).lower():
                raise
            raise FileFormatError(f"{file}: not a {what}: {_why(error)}") from None


def parse_json(text: str, path: str | os.PathLike[str], what: str) -> Any:
    """``json.loads(text)``, a syntax error named with the file and where."""
    try:
        return json.loads(text)
    except json.JSONDecodeError as error:
        raise FileFormatError(f"{os.fspath(path)}: the {what} is not readable JSON ({error})") from None


def load_torch(path: str | os.PathLike[str], what: str, keys: Iterable[str] = ()) -> Any:
    """``torch.load(path, weights_only=True)`` on the CPU; a damaged or foreign file named with what is wrong.

    Parameters
    ----------
    keys : iterable of str
        Keys the checkpoint (a dict) must hold.
    """
    import pickle

    import torch

    file = existing_file(path, what)
    try:
        checkpoint = torch.load(file, map_location="cpu", weights_only=True)
    except (pickle.UnpicklingError, RuntimeError, EOFError, OSError, ValueError, AttributeError) as error:
        raise FileFormatError(f"{file}: not a readable {what} (a PyTorch checkpoint): {_why(error)}") from None
    needed = list(keys)
    if needed:
        if not isinstance(checkpoint, dict):
            raise FileFormatError(f"{file}: a {type(checkpoint).__name__}, not the dict of a {what}")
        missing = [k for k in needed if k not in checkpoint]
        if missing:
            raise FileFormatError(f"{file}: not a {what}: missing {', '.join(map(repr, missing))}")
    return checkpoint
