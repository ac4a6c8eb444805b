"""A batch of runs in one compiled plan: the batch axis, blocks that batch and blocks run per row, snapshots, traces."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from cogblocks.sim import Block, Diagram, DiagramError, Signal, Simulator, Trace
from cogblocks.sim.batch import PerRowWarning


class Leaky(Block):
    """x <- a x + u, y = x; runs a batch at once; ``a`` may hold one value per run."""

    batchable = True

    def __init__(self, a, x0=0.0):
        super().__init__()
        self.a = np.asarray(a, dtype=float)
        self.add_input("u", Signal(), default=self.a * 0.0 + 1.0, feedthrough=False)
        self.add_output("y", Signal())
        self.x0 = x0

    def setup(self):
        self.add_state("x", np.full(self.batch_shape, self.x0) if self.batch_shape else float(self.x0))

    def output(self, k):
        self.y.value[...] = self.x

    def update(self, k):
        u = self.u.value
        # bad data held run by run: a non-finite input leaves that run's state where it was
        x = self.a * self.x + u
        self.x = np.where(np.isfinite(u), x, self.x) if self.batch is not None else (x if np.isfinite(u) else self.x)


class Square(Block):
    """y = u * u + k (k from a per-block counter); written for one run only, so it runs per row in a batch."""

    def __init__(self):
        super().__init__()
        self.add_input("u", Signal())
        self.add_output("y", Signal())
        self.add_state("count", 0)

    def output(self, k):
        self.y.value[...] = float(self.u.value) ** 2 + self.count

    def update(self, k):
        self.count += 1


def chain(a=0.5):
    d = Diagram()
    src = d.add("src", Leaky(a))
    sq = d.add("sq", Square())
    d.connect(src.y, sq.u)
    d.expose_input("u", src.u)
    d.expose_output("y", sq.y)
    return d


def feed(n, batch=None, seed=0):
    rng = np.random.default_rng(seed)
    return rng.normal(size=(n,) if batch is None else (n, batch))


def test_a_batch_of_one_is_the_unbatched_run_bit_for_bit():
    u = feed(200)
    one = Simulator(chain(), probes=["src.y", "sq.y"]).run(n_steps=200, inputs={"u": u})
    with pytest.warns(PerRowWarning, match="'sq' \\(Square\\)"):
        sim = Simulator(chain(), probes=["src.y", "sq.y"], batch=1)
    batched = sim.run(n_steps=200, inputs={"u": u[:, None]})
    assert batched.batch == 1 and batched["sq.y"].shape == (200, 1)
    for name in ("src.y", "sq.y"):
        assert np.array_equal(batched.run(0)[name], one[name])


def test_every_row_is_its_own_run_and_per_row_blocks_are_named():
    u = feed(100, batch=5, seed=1)
    with pytest.warns(PerRowWarning):
        plan = chain().compile(0.01, batch=5)
    assert plan.per_row == ("sq",) and plan.batch == 5
    trace = Simulator(plan, probes=["sq.y"]).run(n_steps=100, inputs={"u": u})
    for b in range(5):
        alone = Simulator(chain(), probes=["sq.y"]).run(n_steps=100, inputs={"u": u[:, b]})
        assert np.array_equal(trace.run(b)["sq.y"], alone["sq.y"])


def test_parameters_per_run_and_their_batch_checked():
    a = np.array([0.1, 0.5, 0.9])
    d = Diagram()
    d.add("x", Leaky(a, x0=1.0))
    trace = Simulator(d, probes=["x.y"], batch=3).run(n_steps=4)
    assert np.allclose(trace["x.y"][3], a * (a * (a + 1) + 1) + 1)  # x <- a x + 1 from 1, read at tick 3
    with pytest.raises(DiagramError, match=r"x.u: its default of shape \(3,\) does not fit a batch of 2"):
        Simulator(d, batch=2)
    with pytest.raises(DiagramError, match="does not fit no batch"):
        Simulator(d)


def test_nan_in_one_run_stays_in_that_run():
    u = feed(50, batch=4, seed=2)
    u[10:20, 2] = np.nan
    d = Diagram()
    d.add("x", Leaky(0.9))
    d.expose_input("u", d["x"].u)
    trace = Simulator(d, probes=["x.y"], batch=4).run(n_steps=50, inputs={"u": u})
    clean = u.copy()
    clean[:, 2] = 0.0
    ref = Simulator(d, probes=["x.y"], batch=4).run(n_steps=50, inputs={"u": clean})
    others = [0, 1, 3]
    assert np.array_equal(trace["x.y"][:, others], ref["x.y"][:, others])
    assert np.isfinite(trace["x.y"]).all()


def test_snapshots_hold_the_whole_batch_and_continue_bit_for_bit(tmp_path):
    u = feed(60, batch=3, seed=3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PerRowWarning)
        sim = Simulator(chain(), probes=["sq.y"], batch=3)
    sim.run(n_steps=30, inputs={"u": u[:30]})
    sim.save_state(tmp_path / "batch.npz")
    state = sim.state_dict()
    assert state["blocks"]["src"]["state"]["x"].shape == (3,)
    assert set(state["blocks"]["sq"]["state"]) == {"0/count", "1/count", "2/count"}
    first = sim.run(n_steps=30, inputs={"u": u[30:]})
    sim.load_state(tmp_path / "batch.npz")
    again = sim.run(n_steps=30, inputs={"u": u[30:]})
    assert np.array_equal(first["sq.y"], again["sq.y"])
    wrong = dict(
        state, blocks={**state["blocks"], "sq": {"state": {"0/count": 1}, "outputs": state["blocks"]["sq"]["outputs"]}}
    )
    with pytest.raises(ValueError, match="run 1|'sq'"):
        sim.load_state_dict(wrong)


def test_batched_inputs_and_steps_have_the_batch_axis():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PerRowWarning)
        plan = chain().compile(0.01, batch=2)
    out = plan.step(u=np.array([1.0, 2.0]))
    assert out["y"].shape == (2,)
    with pytest.raises(ValueError, match=r"expects shape \(2,\)"):
        plan.step(u=1.0)


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, "2"])
def test_a_bad_batch_is_refused(bad):
    with pytest.raises(ValueError, match="batch must be None or a number of runs >= 1"):
        chain().compile(0.01, batch=bad)


def test_a_batched_trace_picks_runs_and_becomes_a_long_frame(tmp_path):
    t = np.arange(3) * 0.01
    trace = Trace(t, {"r": np.arange(6.0).reshape(3, 2), "v": np.arange(12.0).reshape(3, 2, 2)}, batch=2)
    assert np.array_equal(trace.run(1)["v"], [[2, 3], [6, 7], [10, 11]])
    frame = trace.to_pandas(long=True)
    assert list(frame.columns) == ["run", "t", "signal", "element", "value"]
    assert len(frame) == 2 * 3 * (1 + 2)
    row = frame[(frame.run == 1) & (frame.signal == "v") & (frame.element == "1") & (frame.t == 0.02)]
    assert row.value.tolist() == [11.0]
    loaded = Trace.load(trace.save(tmp_path / "t.npz"))
    assert loaded.batch == 2 and np.array_equal(loaded["v"], trace["v"])
    with pytest.raises(ValueError, match="no batch axis"):
        Trace(t, {"r": np.zeros(3)}, batch=2)
    with pytest.raises(IndexError, match=r"\[0, 1\]"):
        trace.run(2)


def test_an_earlier_batched_plan_continues_on_its_copy_after_a_new_compile():
    u = feed(40, batch=3, seed=4)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PerRowWarning)
        d = chain()
        sim = Simulator(d.compile(0.01, batch=3), probes=["sq.y", "src.y"])
        first = sim.run(n_steps=20, inputs={"u": u[:20]})
        d.compile(0.01, batch=3)  # takes the blocks: the earlier plan moves to a private copy, per-row copies too
        second = sim.run(n_steps=20, inputs={"u": u[20:]})
        whole = Simulator(chain(), probes=["sq.y", "src.y"], batch=3).run(n_steps=40, inputs={"u": u})
    for name in ("src.y", "sq.y"):
        assert np.array_equal(np.concatenate([first[name], second[name]]), whole[name])
