"""Option values of the ``cogblocks`` command, checked by argparse so that every error names its option."""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from cogblocks.sim.timing import BASE_STEP

__all__ = ["COUNT", "DURATION", "PLOT_PATH", "POLICY", "SEED", "STEP"]


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


def _policy(text: str) -> str:
    from cogblocks.diagrams.sync import MOTIONS

    if text not in MOTIONS:
        raise ValueError(f"unknown motion computer {text!r} (choose from {', '.join(sorted(MOTIONS))})")
    return text


def _plot_path(text: str) -> str:
    """A figure file that can be written: an existing, writable folder and a format matplotlib saves."""
    from matplotlib.backend_bases import FigureCanvasBase

    path = Path(text)
    formats = FigureCanvasBase.get_supported_filetypes()
    if path.suffix.lower().lstrip(".") not in formats:
        raise ValueError(f"{text!r}: give a file name ending in one of .{', .'.join(sorted(formats))}")
    folder = path.parent
    try:
        if not folder.is_dir():
            raise ValueError(f"{text!r}: no folder {str(folder)!r}")
        if path.is_dir() or not os.access(folder, os.W_OK):
            raise ValueError(f"{text!r}: cannot write a file there")
    except OSError as error:  # e.g. a name too long for the file system
        raise ValueError(f"{text!r}: cannot write a file there ({error.strerror})") from None
    return text


SEED = _option(_integer(0))  # numpy's generators take seeds >= 0
COUNT = _option(_integer(1))
DURATION = _option(_duration)
STEP = _option(_seconds)
POLICY = _option(_policy)
PLOT_PATH = _option(_plot_path)
