"""What the engine keeps for files: a block's constructor call and a trace saved as npz or parquet."""

import copy
import pickle

import numpy as np
import pytest

from cogblocks.sim import Block, Trace


class Scaled(Block):
    def __init__(self, k: float, offset: float = 0.0, *, unit: str = "1", **fields) -> None:
        super().__init__()
        self.k, self.offset = k, offset
        self.add_input("u", unit=unit, **fields)
        self.add_output("y", like="u")


class Spread(Block):
    def __init__(self, *values: float) -> None:
        super().__init__()


def test_init_arguments_by_name():
    block = Scaled(2.0, unit="mm", shape=(3,))
    assert block.init_arguments == {"k": 2.0, "unit": "mm", "shape": (3,)}  # defaults left out, **fields flattened
    assert Scaled(1.0, 0.5).init_arguments == {"k": 1.0, "offset": 0.5}
    assert copy.deepcopy(block).init_arguments == block.init_arguments
    assert pickle.loads(pickle.dumps(block)).init_arguments == block.init_arguments
    with pytest.raises(TypeError, match=r"Spread: a constructor with \*values cannot be described by names"):
        _ = Spread(1.0, 2.0).init_arguments


@pytest.fixture
def trace():
    rng = np.random.default_rng(0)
    t = np.arange(6) * 0.01 + 0.5
    signals = {
        "group.theta": rng.uniform(-np.pi, np.pi, (6, 3)),
        "r": rng.uniform(0, 1, 6),
        "count": np.arange(6, dtype=np.int64),
        "grid": rng.normal(size=(6, 2, 2)).astype(np.float32),
        "ok": np.array([True, False, True, True, False, True]),
    }
    signals["r"][2] = np.nan
    return Trace(t, signals, {"group.theta": "rad", "r": "1"})


@pytest.mark.parametrize("suffix", [".npz", ".parquet"])
def test_trace_round_trip(trace, tmp_path, suffix):
    loaded = Trace.load(trace.save(tmp_path / f"run{suffix}"))
    np.testing.assert_array_equal(loaded.t, trace.t, strict=True)
    assert list(loaded) == list(trace) and loaded.units == trace.units
    for name in trace:
        np.testing.assert_array_equal(loaded[name], trace[name], strict=True)


def test_trace_parquet_columns_and_bad_files(trace, tmp_path):
    import pandas as pd

    frame = pd.read_parquet(trace.save(tmp_path / "run.parquet"))
    assert list(frame.columns[:5]) == ["t", "group.theta[0]", "group.theta[1]", "group.theta[2]", "r"]
    assert "grid[1,0]" in frame.columns
    with pytest.raises(ValueError, match=r"run\.csv: a trace is saved as \.npz or \.parquet"):
        trace.save(tmp_path / "run.csv")
    np.savez(tmp_path / "other.npz", t=trace.t)
    with pytest.raises(ValueError, match=r"other\.npz: not a cogblocks trace"):
        Trace.load(tmp_path / "other.npz")
