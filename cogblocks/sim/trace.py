"""Traces: the recorded signals of a run, as NumPy arrays with a time vector."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np

__all__ = ["Trace"]


class Trace(Mapping[str, np.ndarray]):
    """Recorded signals of a run.

    A read-only mapping from probe name to an array of shape
    ``(n_samples, *signal_shape)``, with the sample times in :attr:`t`.

    Attributes
    ----------
    t : numpy.ndarray
        Sample times in seconds, shape ``(n_samples,)``.
    units : dict
        Unit of each signal.
    """

    def __init__(
        self, t: np.ndarray, signals: Mapping[str, np.ndarray], units: Mapping[str, str] | None = None
    ) -> None:
        self.t = np.asarray(t, dtype=float)
        self._signals = dict(signals)
        for name, arr in self._signals.items():
            if len(arr) != len(self.t):
                raise ValueError(f"signal {name!r} has {len(arr)} samples but the time vector has {len(self.t)}")
        self.units = dict(units or {})

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self._signals[name]
        except KeyError:
            raise KeyError(f"no signal {name!r} in the trace; recorded: {list(self._signals)}") from None

    def __iter__(self) -> Iterator[str]:
        return iter(self._signals)

    def __len__(self) -> int:
        return len(self._signals)

    def __repr__(self) -> str:
        span = f"{self.t[0]:g}..{self.t[-1]:g} s" if len(self.t) else "empty"
        return f"<Trace {len(self.t)} samples, {span}: {', '.join(self._signals)}>"

    def plot(self, *names: str, ax: Any = None) -> Any:
        """Plot signals against time with matplotlib (all of them by default); returns the axes."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots()
        for name in names or tuple(self._signals):
            arr = self[name]
            lines = ax.plot(self.t, arr.reshape(len(arr), -1))
            for i, line in enumerate(lines):
                line.set_label(name if len(lines) == 1 else f"{name}[{i}]")
        ax.set_xlabel("t [s]")
        ax.legend(loc="best")
        return ax

    def to_pandas(self) -> Any:
        """A ``pandas.DataFrame`` indexed by time; vector signals become ``name[i]`` columns."""
        import pandas as pd

        columns: dict[str, np.ndarray] = {}
        for name, arr in self._signals.items():
            if arr.ndim == 1:
                columns[name] = arr
            else:
                flat = arr.reshape(len(arr), -1)
                for idx in np.ndindex(*arr.shape[1:]):
                    j = int(np.ravel_multi_index(idx, arr.shape[1:]))
                    columns[f"{name}[{','.join(map(str, idx))}]"] = flat[:, j]
        return pd.DataFrame(columns, index=pd.Index(self.t, name="t"))
