"""Every file the project reads, fed truncated, empty, garbage and wrong-type files: the error names the file and
what is wrong, never advises unsafe loading, and is never a raw BadZipFile, JSONDecodeError or UnpicklingError."""

import json
import pickle
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
import scipy.io
import torch

from cogblocks.amplification import load_encoder
from cogblocks.amplification.corrector import load_corrector
from cogblocks.amplification.encoder import EncoderNet
from cogblocks.amplification.judges import load_ensemble
from cogblocks.amplification.solution import solution_table
from cogblocks.amplification.subspace import MovementSubspace, load_subspace
from cogblocks.blocks import Constant, Integrator
from cogblocks.data.loaders import load_csv, load_npz, load_velocity_data_mat, save_csv, save_npz
from cogblocks.data.reach import generate_reach_library
from cogblocks.experiments.files import load_diagram, save_diagram
from cogblocks.sim import Diagram, Simulator, Trace
from cogblocks.sim.snapshot import load_snapshot
from cogblocks.sync.dqn_policy import DQNPolicy

WEIGHTS = Path(__file__).parents[2] / "cogblocks" / "data" / "weights"


def _diagram():
    d = Diagram()
    d.add("c", Constant(1.0))
    d.add("x", Integrator(unit="1"))
    d.connect("c.y", "x.u")
    return d


def _snapshot(path):
    sim = Simulator(_diagram())
    sim.run(n_steps=3)
    sim.compiled.save_state(path)


def _trace(path):
    Trace(np.arange(3) * 0.01, {"x": np.arange(3.0)}, {"x": "1"}).save(path)


def _library(path, save):
    save(generate_reach_library(0, n_subjects=2, n_fear=2, n_no_fear=2), path)


def _mat_library(path):
    """The MATLAB layout of the real data: one participant, a struct array of three baseline trials."""
    fields = ("Condition", "Phase", "Subphase", "Vxyzf", "Trial_Number")
    trials = np.empty((1, 3), dtype=[(field, object) for field in fields])
    for k in range(3):
        velocity = np.random.default_rng(k).normal(0.0, 300.0, (40, 3))
        for field, value in zip(fields, (0, "BASELINE", 1, velocity, k + 1), strict=True):
            trials[0, k][field] = value
    scipy.io.savemat(path, {"VelocityData": {"P01": trials}})


def _subspace(path):
    MovementSubspace(np.zeros(3), np.eye(2, 3), 0.5, 1).save(path)


READERS = {
    "snapshot": (".npz", _snapshot, load_snapshot),
    "trace npz": (".npz", _trace, Trace.load),
    "trace parquet": (".parquet", _trace, Trace.load),
    "diagram": (".json", lambda p: save_diagram(_diagram(), p), load_diagram),
    "library npz": (".npz", lambda p: _library(p, save_npz), load_npz),
    "library csv": (".csv", lambda p: _library(p, save_csv), load_csv),
    "library mat": (".mat", _mat_library, load_velocity_data_mat),
    "subspace": (".npz", _subspace, load_subspace),
    "encoder weights": (".pt", lambda p: shutil.copy(WEIGHTS / "encoder.pt", p), load_encoder),
    "corrector weights": (".pt", lambda p: shutil.copy(WEIGHTS / "corrector.pt", p), load_corrector),
    "judge weights": (".pt", lambda p: shutil.copy(WEIGHTS / "judges.pt", p), load_ensemble),
    "dqn weights": (".pt", lambda p: shutil.copy(WEIGHTS / "sync_dqn.pt", p), DQNPolicy.from_file),
}


def _wrong_type(path, suffix):
    """A valid file of another kind under the same suffix."""
    if suffix == ".npz":
        np.savez(path, unrelated=np.arange(4))
    elif suffix == ".json":
        path.write_text(json.dumps([1, 2, 3]))
    elif suffix == ".pt":
        torch.save(torch.zeros(3), path)
    elif suffix == ".mat":
        scipy.io.savemat(path, {"Kinematics": np.zeros(3)})
    elif suffix == ".parquet":
        import pyarrow as pa
        import pyarrow.parquet as pq

        pq.write_table(pa.table({"a": [1, 2]}), path)
    else:
        path.write_text("a,b\n1,2\n")


CORRUPTIONS = ["truncated", "empty", "garbage", "wrong type", "pickle"]


def _corrupt(path, corruption, suffix):
    good = path.read_bytes()
    if corruption == "truncated":
        path.write_bytes(good[: len(good) // 2])
    elif corruption == "empty":
        path.write_bytes(b"")
    elif corruption == "garbage":
        path.write_bytes(np.random.default_rng(0).bytes(4096))
    elif corruption == "pickle":
        path.write_bytes(pickle.dumps({"a": object.__name__}))  # what an unsafe reader would execute
    else:
        _wrong_type(path, suffix)


@pytest.mark.parametrize("corruption", CORRUPTIONS)
@pytest.mark.parametrize("reader", sorted(READERS))
def test_a_bad_file_is_named_with_what_is_wrong(tmp_path, reader, corruption):
    suffix, write, read = READERS[reader]
    path = tmp_path / f"file{suffix}"
    write(path)
    read(path)  # the valid file reads
    _corrupt(path, corruption, suffix)
    with pytest.raises((ValueError, OSError)) as caught:
        read(path)
    error = caught.value
    message = str(error)
    assert str(path) in message or getattr(error, "filename", None) == str(path), message
    assert "allow_pickle" not in message and "weights_only" not in message, message
    assert not isinstance(error, (zipfile.BadZipFile, json.JSONDecodeError, pickle.UnpicklingError, UnicodeError))
    assert type(error) not in (ValueError, OSError) or len(message) > len(str(path)) + 5  # it says what is wrong


@pytest.mark.parametrize("corruption", CORRUPTIONS)
def test_a_bad_solution_cache_is_named_and_rebuilt(tmp_path, corruption):
    """The w̃ cache is the project's own file, so a bad one is not an error: it is named in a warning and rebuilt."""
    torch.manual_seed(0)
    network = EncoderNet(hidden=4).double().eval()
    library = generate_reach_library(0, n_subjects=2, n_fear=2, n_no_fear=2)
    first = solution_table(network, library, grid_points=4, cache_dir=tmp_path)
    (path,) = tmp_path.glob("w_tilde_*.npz")
    _corrupt(path, corruption, ".npz")
    with pytest.warns(UserWarning, match="corrupt w̃ cache file") as record:
        again = solution_table(network, library, grid_points=4, cache_dir=tmp_path)
    message = str(record[0].message)
    assert str(path) in message and "allow_pickle" not in message, message
    np.testing.assert_array_equal(again.values, first.values)
    with np.load(path) as rebuilt:
        np.testing.assert_array_equal(rebuilt["values"], first.values)
