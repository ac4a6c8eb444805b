"""Sweeps: the same DataFrame serially, on loky and on a Dask LocalCluster; failures kept with their seed."""

import sys
import warnings

import cloudpickle
import numpy as np
import pandas as pd
import pytest

from cogblocks.blocks import Probe
from cogblocks.experiments.sweep import SweepWarning, grid_points, save_results, sweep, sweep_seeds
from cogblocks.sim import Diagram, Simulator
from cogblocks.sync import KuramotoGroup, OrderParameter

# the test module is not importable by the workers: send its functions by value
cloudpickle.register_pickle_by_value(sys.modules[__name__])

GRID = {"gain": [0.5, 2.0], "spread": [0.2, 1.0]}
N_STEPS = 200


def kuramoto(gain, spread, seed):
    """Four oscillators with frequencies and initial phases drawn from the seed."""
    rng = np.random.default_rng(seed)
    omega = 2 * np.pi + spread * rng.standard_normal(4)
    d = Diagram()
    group = d.add("group", KuramotoGroup(omega, gain, theta0=rng.uniform(-np.pi, np.pi, 4)))
    order = d.add("order", OrderParameter())
    d.connect(group.theta, order.theta)
    d.add("r", Probe())
    d.connect(order.r, "r.u")
    return d


def measure(trace):
    return {"r_mean": float(trace["r"].mean()), "r_final": float(trace["r"][-1])}


def run(backend, **kwargs):
    return sweep(kuramoto, GRID, seeds=3, measure=measure, n_steps=N_STEPS, backend=backend, progress=False, **kwargs)


@pytest.fixture(scope="module")
def serial():
    return run("serial")


@pytest.fixture(scope="module")
def dask_client():
    distributed = pytest.importorskip("distributed", reason="the cluster extra (dask[distributed]) is not installed")
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=False, protocol="tcp", host="127.0.0.1", dashboard_address=None
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        yield client


def test_long_form_against_direct_runs(serial):
    seeds = [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(0).spawn(3)]
    assert list(serial.columns) == ["gain", "spread", "replicate", "seed", "r_mean", "r_final", "error"]
    assert len(serial) == 4 * 3
    assert serial["seed"].tolist() == seeds * 4
    assert serial[["gain", "spread"]].drop_duplicates().to_dict("records") == grid_points(GRID)
    assert serial["error"].isna().all()
    for row in serial.itertuples():
        trace = Simulator(kuramoto(row.gain, row.spread, row.seed)).run(n_steps=N_STEPS)
        assert row.r_mean == float(trace["r"].mean())
        assert row.r_final == float(trace["r"][-1])
    # stronger coupling synchronises more, on every seed
    weak = serial[serial["gain"] == 0.5]["r_final"].to_numpy()
    strong = serial[serial["gain"] == 2.0]["r_final"].to_numpy()
    assert (strong > weak).mean() > 0.5


def test_seeds_come_from_seed_sequence_spawn():
    assert sweep_seeds(4, 7) == [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(7).spawn(4)]
    assert sweep_seeds(2, 7) == sweep_seeds(4, 7)[:2]  # more replicates keep the first ones
    with pytest.raises(ValueError, match="seeds must be an integer >= 1"):
        sweep_seeds(0)


def test_loky_gives_the_same_frame(serial):
    pd.testing.assert_frame_equal(run("loky", n_jobs=2, batch_size=1), serial)


def test_dask_gives_the_same_frame(serial, dask_client):
    pd.testing.assert_frame_equal(run("dask", client=dask_client, batch_size=5), serial)


def test_batching_and_worker_count_do_not_change_the_result(serial):
    pd.testing.assert_frame_equal(run("serial", batch_size=7, n_jobs=3), serial)


def failing(gain, seed):
    if gain < 0:
        raise ValueError(f"negative gain {gain}")
    return kuramoto(gain, 0.5, seed)


@pytest.mark.parametrize("backend", ["serial", "loky", "dask"])
def test_a_failing_task_is_reported_and_the_others_kept(backend, request):
    kwargs = {"client": request.getfixturevalue("dask_client")} if backend == "dask" else {"n_jobs": 2}
    with pytest.warns(SweepWarning, match=r"2 of 6 sweep tasks failed.*'gain': -1\.0.*'seed': \d+"):
        df = sweep(
            failing,
            {"gain": [0.5, -1.0, 2.0]},
            seeds=2,
            measure=measure,
            n_steps=50,
            backend=backend,
            progress=False,
            **kwargs,
        )
    bad = df[df["gain"] == -1.0]
    assert bad["error"].iloc[0] == "ValueError: negative gain -1.0"
    assert bad["error"].iloc[1] == "ValueError: negative gain -1.0"
    assert bad["r_mean"].isna().all()
    good = df[df["gain"] != -1.0]
    assert good["error"].isna().all() and good["r_mean"].between(0, 1).all()
    assert [f["seed"] for f in df.attrs["failures"]] == bad["seed"].tolist()


def test_a_run_function_and_bad_arguments():
    def build(n, seed):
        return lambda: Simulator(kuramoto(1.0, 0.5, seed)).run(n_steps=n)

    df = sweep(build, [{"n": 5}, {"n": 9}], measure=lambda t: {"samples": len(t.t)}, backend="serial")
    assert df["samples"].tolist() == [5, 9]
    with pytest.raises(ValueError, match="backend must be one of"):
        sweep(build, {"n": [1]}, measure=measure, backend="threads")
    with pytest.raises(ValueError, match=r"grid\['n'\] must be a sequence"):
        sweep(build, {"n": 3}, measure=measure, backend="serial")


def test_results_saved_as_parquet_and_csv(serial, tmp_path):
    frame = serial.drop(columns="error")
    pd.testing.assert_frame_equal(pd.read_parquet(save_results(serial, tmp_path / "s.parquet")), serial)
    pd.testing.assert_frame_equal(pd.read_csv(save_results(serial, tmp_path / "s.csv")).drop(columns="error"), frame)
    with pytest.raises(ValueError, match="saved as .parquet or .csv"):
        save_results(serial, tmp_path / "s.xlsx")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert not serial.attrs["failures"]
