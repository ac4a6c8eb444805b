"""Traces: the recorded signals of a run, as NumPy arrays with a time vector."""

from __future__ import annotations

import json
import os
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["Trace"]


class Trace(Mapping[str, np.ndarray]):
    """Recorded signals of a run.

    A read-only mapping from probe name to an array of shape
    ``(n_samples, *signal_shape)``, with the sample times in :attr:`t`. A trace of a batch of
    runs (``batch=B``) holds arrays of shape ``(n_samples, B, *signal_shape)``: at each sample, the
    batched signal; :meth:`run` picks one run.

    Attributes
    ----------
    t : numpy.ndarray
        Sample times in seconds, shape ``(n_samples,)``.
    units : dict
        Unit of each signal.
    batch : int or None
        Runs in the trace (the axis after time), or ``None`` for a trace of one run without a batch axis.
    """

    def __init__(
        self,
        t: np.ndarray,
        signals: Mapping[str, np.ndarray],
        units: Mapping[str, str] | None = None,
        *,
        batch: int | None = None,
    ) -> None:
        self.t = np.asarray(t, dtype=float)
        self._signals = dict(signals)
        for name, arr in self._signals.items():
            if len(arr) != len(self.t):
                raise ValueError(f"signal {name!r} has {len(arr)} samples but the time vector has {len(self.t)}")
            if batch is not None and (np.ndim(arr) < 2 or np.shape(arr)[1] != batch):
                raise ValueError(f"signal {name!r} of shape {np.shape(arr)} has no batch axis of {batch} runs")
        self.units = dict(units or {})
        self.batch = batch

    def run(self, b: int) -> Trace:
        """The trace of run ``b`` of a batch (views, no copies), without the batch axis."""
        if self.batch is None:
            raise ValueError("run(b) picks one run of a batched trace; this trace has no batch axis")
        if isinstance(b, bool) or not isinstance(b, (int, np.integer)) or not -self.batch <= b < self.batch:
            raise IndexError(f"run must be an index in [0, {self.batch - 1}], got {b!r}")
        return Trace(self.t, {name: arr[:, b] for name, arr in self._signals.items()}, self.units)

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

    def to_pandas(self, *, long: bool = False) -> Any:
        """A ``pandas.DataFrame`` indexed by time; vector signals become ``name[i]`` columns.

        ``long=True`` gives the long ("tidy") frame instead, one row per sample, element (and run)
        of every signal: columns ``run`` (batched traces only), ``t``, ``signal``, ``element``
        (``""`` for a scalar, ``"i"`` or ``"i,j"`` for an element) and ``value``.
        """
        import pandas as pd

        if long:
            return self._long(pd)
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

    def _long(self, pd: Any) -> Any:
        runs = [(None, self)] if self.batch is None else [(b, self.run(b)) for b in range(self.batch)]
        frames = []
        for b, one in runs:
            for name, arr in one._signals.items():
                n, shape = len(arr), arr.shape[1:]
                flat = np.asarray(arr, dtype=float).reshape(n, -1)
                labels = [",".join(map(str, idx)) for idx in np.ndindex(*shape)]
                frame = {"t": np.repeat(self.t, len(labels)), "signal": name}
                frame["element"] = np.tile(np.array(labels, dtype=object), n)
                frame["value"] = flat.reshape(-1)
                frames.append(pd.DataFrame(frame if b is None else {"run": b, **frame}))
        columns = (
            ["t", "signal", "element", "value"] if self.batch is None else ["run", "t", "signal", "element", "value"]
        )
        return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=columns)

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the trace to ``path``: ``.npz`` (NumPy, no pickles) or ``.parquet`` (pyarrow).

        Both keep the time axis, every signal's shape and dtype, and the units; a vector signal
        becomes columns ``name[i]`` in Parquet. Returns the path.
        """
        path = Path(path)
        names = list(self._signals)
        meta = {
            "format": _TRACE_FORMAT,
            "signals": names,
            "units": self.units,
            "shapes": {name: list(self._signals[name].shape[1:]) for name in names},
            "batch": self.batch,
        }
        kind = _trace_kind(path)
        if kind == "npz":
            arrays = {f"signal{i}": np.asarray(self._signals[name]) for i, name in enumerate(names)}
            np.savez(path, t=self.t, meta=np.array(json.dumps(meta)), **arrays)
            return path
        import pyarrow as pa
        import pyarrow.parquet as pq

        columns: dict[str, np.ndarray] = {"t": self.t}
        for name in names:
            arr = np.asarray(self._signals[name])
            flat = arr.reshape(len(arr), -1)
            if arr.ndim == 1:
                columns[name] = arr
            else:
                for j, idx in enumerate(np.ndindex(*arr.shape[1:])):
                    columns[f"{name}[{','.join(map(str, idx))}]"] = flat[:, j]
        table = pa.table(columns).replace_schema_metadata({"cogblocks": json.dumps(meta)})
        pq.write_table(table, path)
        return path

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Trace:
        """Read a trace written by :meth:`save` (``.npz`` or ``.parquet``)."""
        path = Path(path)
        if _trace_kind(path) == "npz":
            from cogblocks.sim.reading import open_npz

            with open_npz(path, "cogblocks trace") as stored:
                meta = _trace_meta(path, str(stored["meta"]) if "meta" in stored.files else None)
                signals = {name: stored[f"signal{i}"] for i, name in enumerate(meta["signals"])}
                return cls(stored["t"], signals, meta["units"], batch=meta.get("batch"))
        import pyarrow.parquet as pq

        from cogblocks.sim.reading import FileFormatError, existing_file

        try:
            table = pq.read_table(existing_file(path, "cogblocks trace"))
        except (OSError, ValueError) as error:  # pyarrow's ArrowInvalid is a ValueError
            if isinstance(error, (FileNotFoundError, IsADirectoryError, FileFormatError)):
                raise
            raise FileFormatError(f"{path}: not a readable cogblocks trace (a Parquet file): {error}") from None
        raw = (table.schema.metadata or {}).get(b"cogblocks")
        meta = _trace_meta(path, None if raw is None else raw.decode())
        t = table.column("t").to_numpy()
        signals = {}
        for name in meta["signals"]:
            shape = tuple(meta["shapes"][name])
            if not shape:
                signals[name] = table.column(name).to_numpy()
                continue
            cols = [table.column(f"{name}[{','.join(map(str, idx))}]").to_numpy() for idx in np.ndindex(*shape)]
            signals[name] = np.stack(cols, axis=1).reshape((len(t), *shape))
        return cls(t, signals, meta["units"], batch=meta.get("batch"))


_TRACE_FORMAT = "cogblocks.trace/1"


def _trace_kind(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in (".npz", ".parquet"):
        raise ValueError(f"{path}: a trace is saved as .npz or .parquet, got {suffix or 'no suffix'!r}")
    return suffix[1:]


def _trace_meta(path: Path, raw: str | None) -> dict[str, Any]:
    from cogblocks.sim.reading import parse_json

    meta = None if raw is None else parse_json(raw, path, "trace's metadata")
    if not isinstance(meta, dict) or meta.get("format") != _TRACE_FORMAT:
        raise ValueError(f"{path}: not a cogblocks trace (no {_TRACE_FORMAT!r} metadata)")
    return meta
