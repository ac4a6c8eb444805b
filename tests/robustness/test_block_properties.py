"""Every public block against bad sensor data: NaN, ±inf, 1e300, frozen runs and spikes (hypothesis).

Each block runs alone in a diagram that exposes all its inputs and outputs, driven tick by tick with
``compiled.step(**inputs)`` (Playback refuses inf; ``step`` takes anything). There is one case per
(block, input): that input gets a stream broken by glitches while the others stay clean, so that a
failure names the input that caused it ("*" glitches every sample input of blocks whose input names
depend on their parameters). The block must keep the bad-data policy of its docstring:

* outputs are finite, except where the docstring lets a non-finite value out (Saturation passes NaN,
  BackwardDifference turns a bad sample into a bad output, KalmanEstimator is NaN before its first
  sample, ...);
* where the docstring says that an output holds on bad data, it equals its value of the tick before;
* wrapped phases stay in [0, 2π);
* no exception unless the docstring documents it, and no RuntimeWarning (NumPy's "invalid value" and
  "overflow" warnings are errors here, as they are for cogblocks in the rest of the suite).

A block whose docstring says nothing about bad data is held to "finite outputs": a NaN that comes out
silently is a failure. Known violations are strict xfails (``VIOLATIONS``), so that fixing the block
makes the case fail until its entry is removed.

Blocks are found through ``FACTORIES`` (block class -> valid instances, how to feed them, policy);
``test_every_public_block_has_a_factory`` fails when a public block has none.
"""

from __future__ import annotations

import inspect
import math
import re
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, assume, given, settings
from hypothesis import strategies as st

import cogblocks.catalogue as catalogue
from cogblocks.blocks import (
    BackwardDifference,
    Constant,
    Demux,
    DiscreteLTI,
    Function,
    Gain,
    Integrator,
    LowPass,
    Mux,
    Playback,
    Probe,
    Saturation,
    Select,
    Substitute,
    Sum,
    UnitDelay,
)
from cogblocks.phase import (
    Algorithm1Phase,
    PeriodEstimator,
    PhaseComputer,
    PhaseEstimator,
    PhaseEstimator3D,
    PhasePositionComputer,
    ReferenceCustomizer,
)
from cogblocks.sensing import L1, KalmanEstimator, KinematicPredictor, RestGate
from cogblocks.sim import Diagram, Signal, SimulationError
from cogblocks.sync import (
    ArmPositions,
    Blender,
    KuramotoGroup,
    KuramotoOscillator,
    MeanPhaseMotion,
    MotionComputer,
    OrderParameter,
    OscillatorMotion,
    SettledHandover,
)

TWO_PI = 2.0 * math.pi
TICKS = st.integers(20, 40)  # a few dozen ticks: filters start, frozen runs get confirmed

# Deterministic (derandomised, no example database) and sized for about a minute on two shared cores;
# no shrinking, which would cost minutes on every known violation (the xfails below): add Phase.shrink
# to ``phases`` to get a minimal failing example while fixing a block.
ROBUST = settings(
    max_examples=40,
    deadline=None,
    derandomize=True,
    database=None,
    phases=(Phase.explicit, Phase.generate),
    report_multiple_bugs=False,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
)


# -- input streams ------------------------------------------------------------------------------------

BAD = {"nan": math.nan, "inf": math.inf, "-inf": -math.inf, "huge": 1e300, "-huge": -1e300}
ALL_GLITCHES = (*BAD, "frozen", "spike")
# for inputs whose docstring makes the block upstream responsible for replacing non-finite samples
FINITE_GLITCHES = ("huge", "-huge", "frozen", "spike")


@st.composite
def signal(draw, n: int, shape: tuple[int, ...], *, scale=100.0, offset=0.0, wrapped=False, glitches=()):
    """``n`` samples of ``shape``: noisy sinusoids broken by 1 to 6 segments of ``glitches``.

    Hypothesis draws the seed of the clean signal and the plan of the glitches (kind, start, length,
    all elements or some), so that, with shrinking on, a failure shrinks to few, short segments.
    """
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    size = math.prod(shape)
    t = np.arange(n)[:, None] * 0.01
    x = offset + scale * (
        np.cos(TWO_PI * rng.uniform(0.3, 2.0, size) * t + rng.uniform(0, TWO_PI, size))
        + 0.02 * rng.standard_normal((n, size))
    )
    if wrapped:
        x = np.mod(x, TWO_PI)
    if glitches:
        plan = st.tuples(st.sampled_from(glitches), st.integers(0, n - 1), st.integers(1, 8), st.booleans())
        for kind, start, length, whole in draw(st.lists(plan, min_size=1, max_size=6)):
            rows = slice(start, min(n, start + length))
            cols = np.ones(size, bool) if whole or size == 1 else rng.random(size) < 0.5
            if kind == "frozen":  # a tracker repeating its last sample
                x[rows] = x[max(start - 1, 0)]
            elif kind == "spike":
                x[rows, cols] += rng.choice([-50.0, 50.0]) * scale
            else:
                x[rows, cols] = BAD[kind]
    return x.reshape((n, *shape))


def counter(n: int):
    """A count that starts at 0 and goes up by 0 or 1 per tick, as period and decision counters do."""
    return st.lists(st.booleans(), min_size=n, max_size=n).map(lambda steps: np.cumsum(steps).astype(np.int64))


def int_list(n: int, low: int, high: int):
    return st.lists(st.integers(low, high), min_size=n, max_size=n).map(lambda v: np.array(v, dtype=np.int64))


@dataclass(frozen=True)
class Feed:
    """How to drive one input: the spec to expose it with, and a strategy for its ``n`` samples.

    ``stream(n, glitches)`` gets the glitches for the input under test and ``()`` for the others;
    counters and flags (``samples=False``) carry other blocks' decisions, not sensor samples, and
    always get valid values.
    """

    spec: Signal
    stream: Callable[[int, tuple], st.SearchStrategy]
    samples: bool = True


def floats(shape=(), unit="1", *, wrapped=False, scale=100.0, offset=0.0, finite_only=False) -> Feed:
    def stream(n, glitches):
        if finite_only and glitches:
            glitches = FINITE_GLITCHES
        return signal(n, tuple(shape), scale=scale, offset=offset, wrapped=wrapped, glitches=glitches)

    return Feed(Signal(shape=shape, unit=unit, wrapped=wrapped), stream)


def phase(shape=()) -> Feed:
    return floats(shape, "rad", wrapped=True)


def ints(make: Callable[[int], st.SearchStrategy]) -> Feed:
    return Feed(Signal(dtype=np.int64), lambda n, _: make(n), samples=False)


def bools() -> Feed:
    return Feed(Signal(dtype=bool), lambda n, _: st.lists(st.booleans(), min_size=n, max_size=n).map(np.array), False)


# -- policies -------------------------------------------------------------------------------------------


def bad(value) -> bool:
    """Whether a sample has a non-finite element."""
    return not np.all(np.isfinite(value))


@dataclass(frozen=True)
class Policy:
    """A block's bad-data policy, as its docstring states it.

    nonfinite : output -> ``allowed(inputs of the tick, inputs of every tick so far)``: when that output
        may be non-finite (never, for outputs not listed).
    holds : output -> ``holds(block, inputs of the tick, inputs of every tick so far)``: when the output
        keeps its previous value.
    outside : output -> ``allowed(inputs of the tick, inputs of every tick so far)``: when a finite value of
        that wrapped output may lie outside [0, 2π) (a phase passed on as given).
    check : an extra assertion ``check(block, k, inputs, outputs, previous outputs, inputs so far)``.
    raises : documented exceptions, which end the run; ``raises_when(block, k, exception)`` says whether
        this one was due (and its message clear).
    """

    nonfinite: dict[str, Callable[[dict, list], bool]] = field(default_factory=dict)
    holds: dict[str, Callable[[Any, dict, list], bool]] = field(default_factory=dict)
    outside: dict[str, Callable[[dict, list], bool]] = field(default_factory=dict)
    check: Callable[..., None] | None = None
    raises: tuple[type[BaseException], ...] = ()
    raises_when: Callable[[Any, int, BaseException], bool] = lambda block, k, exc: False


def when_bad(*names):
    """Non-finite allowed on a tick where one of these inputs is non-finite (the bad sample passes)."""
    return lambda ins, seen: any(bad(ins[n]) for n in names)


def until_finite(name):
    """Non-finite allowed until the input has carried one all-finite sample (nothing to estimate yet)."""
    return lambda ins, seen: all(bad(past[name]) for past in seen)


def until_usable(name, bound=1e9):
    """Non-finite allowed until the input has carried a sample the Kalman filter uses: finite and below
    ``bound`` (its corrupted-value limit: a larger finite value is missing data, like NaN)."""
    return lambda ins, seen: all(bad(past[name]) or np.any(np.abs(past[name]) >= bound) for past in seen)


def flags_held(name):
    """Check: a tick whose ``name`` input is non-finite is flagged ``held`` (the phase is extrapolated)."""

    def check(block, k, ins, outs, previous, seen):
        if bad(ins[name]):
            assert outs["held"], f"{type(block).__name__} did not flag the missing sample {ins[name]} as held"

    return check


def input_bad(*names):
    """Hold predicate: one of these inputs is non-finite."""
    return lambda block, ins, seen: any(bad(ins[n]) for n in names)


@dataclass(frozen=True)
class Factory:
    """Valid instances, the feed of each input, the cases (sample inputs to glitch) and the policy.

    ``couple(block, streams)`` rewrites streams that other blocks keep consistent with each other
    (the flag of a missing sample, the filtered copy of a raw signal).
    """

    block: st.SearchStrategy
    feeds: Callable[[Any], dict[str, Feed]]
    targets: tuple[str, ...]
    policy: Policy = Policy()
    couple: Callable[[Any, dict], dict] | None = None


FACTORIES: dict[type, Factory] = {}


def register(cls, block, feeds=lambda b: {}, targets=None, policy=Policy(), couple=None) -> None:
    FACTORIES[cls] = Factory(block, feeds, tuple(targets or ()), policy, couple)


def fed_as(block, shape):
    """Remember the shape the test feeds a generic block (which takes its spec from its driver)."""
    block.test_shape = shape
    return block


def concrete(port, spec: Signal) -> Signal:
    """The port's declared spec with its open fields filled from the feed's spec."""
    declared = getattr(port, "declared", port.spec)
    return Signal(
        shape=declared.shape if declared.shape is not None else spec.shape,
        dtype=declared.dtype if declared.dtype is not None else spec.dtype,
        unit=declared.unit if declared.unit is not None else spec.unit,
        wrapped=declared.wrapped if declared.wrapped is not None else spec.wrapped,
    )


def drive(block, feeds: dict[str, Feed], streams: dict[str, np.ndarray], n: int, policy: Policy) -> None:
    """Run the block alone for ``n`` ticks and assert its policy at every tick."""
    d = Diagram()
    d.add("b", block)
    for name, feed in feeds.items():
        d.expose_input(name, block.inputs[name], spec=concrete(block.inputs[name], feed.spec))
    for name, port in block.outputs.items():
        d.expose_output(name, port)
    compiled = d.compile()
    previous = {name: compiled.output_port(name).value.copy() for name in block.outputs}
    wrapped = {name: compiled.output_port(name).spec.wrapped for name in block.outputs}
    seen: list[dict] = []
    label = type(block).__name__
    for k in range(n):
        ins = {name: streams[name][k] for name in feeds}
        seen.append(ins)
        with warnings.catch_warnings(), np.errstate(all="warn", under="ignore"):
            warnings.simplefilter("error", RuntimeWarning)  # a NumPy warning is a failure too
            try:
                outs = compiled.step(**ins)
            except policy.raises as exc:
                assert policy.raises_when(block, k, exc), f"{label} raised {exc!r} at tick {k} on {ins}"
                return
            except Exception as exc:
                raise AssertionError(f"{label} raised {type(exc).__name__}: {exc}\n at tick {k} on {ins}") from exc
        for out, value in outs.items():
            value = np.asarray(value)
            where = f"{label}.{out} = {value!r} at tick {k} on {ins}"
            if value.dtype.kind == "f" and bad(value):
                allowed = policy.nonfinite.get(out)
                assert allowed is not None and allowed(ins, seen), f"non-finite output {where}"
            if wrapped[out] and not bad(value) and not np.all((value >= 0.0) & (value < TWO_PI)):
                allowed = policy.outside.get(out)
                assert allowed is not None and allowed(ins, seen), f"phase outside [0, 2π): {where}"
            holds = policy.holds.get(out)
            if holds is not None and holds(block, ins, seen):
                assert np.array_equal(value, previous[out], equal_nan=True), f"{where} does not hold {previous[out]!r}"
        if policy.check is not None:
            policy.check(block, k, ins, outs, previous, seen)
        previous = {out: np.array(value) for out, value in outs.items()}


# -- strategies shared by several factories ------------------------------------------------------------

SHAPES = st.sampled_from([(), (1,), (3,), (2, 2)])
finite = st.floats(-1e3, 1e3)
seeds = st.integers(0, 2**31 - 1)


def generic(make: st.SearchStrategy, shapes=SHAPES) -> st.SearchStrategy:
    """A generic block drawn together with the shape the test feeds it."""
    return st.tuples(make, shapes).map(lambda bs: fed_as(*bs))


@st.composite
def curve(draw, min_size=2, max_size=40):
    """A closed 3D reference curve (a tilted figure of eight, mm), one cycle from phase 0."""
    n = draw(st.integers(min_size, max_size))
    rng = np.random.default_rng(draw(seeds))
    phi = TWO_PI * np.arange(n) / n
    axes = rng.uniform(20.0, 200.0, 3)
    xyz = np.stack([axes[0] * np.cos(phi), axes[1] * np.sin(phi), axes[2] * np.sin(2 * phi)], axis=1)
    return xyz @ np.linalg.qr(rng.standard_normal((3, 3)))[0] + rng.uniform(-500, 500, 3)


def kalman():
    return st.builds(
        KalmanEstimator,
        st.sampled_from(["cv", "ca"]),
        process_noise=st.none() | st.floats(1e2, 1e8),
        measurement_noise=st.floats(0.1, 10.0),
        gate=st.none() | st.floats(0.9, 0.9999),
        max_rejections=st.integers(1, 6),
        freeze_frames=st.none() | st.integers(1, 4),
    )


ALGORITHM1 = {
    "centre_periods": st.integers(1, 3),
    "accel_window": st.floats(0.0, 0.1),
    "min_dropout": st.floats(0.0, 0.1),
    "holdoff": st.floats(0.0, 0.5),
    "max_period": st.floats(0.5, 5.0),
    "order": st.integers(1, 4),
}


def period_kwargs(draw) -> dict:
    return {
        "h": draw(st.floats(0.02, 0.05)),  # s: 2-5 samples at the harness's 10 ms step
        "capacity": draw(st.integers(13, 60)),
        "start_speed": draw(st.floats(0.0, 200.0)),
        "match_ratio": draw(st.floats(0.05, 1.0)),
        "min_period_fraction": draw(st.floats(0.0, 0.95)),
    }


def search_kwargs(draw) -> dict:
    return {
        "search": draw(st.sampled_from(["warm", "full"])),
        "window": draw(st.floats(0.01, 0.5)),
        "jump_factor": draw(st.floats(1.01, 10.0)),
        "distance_floor": draw(st.floats(0.0, 20.0)),
        "velocity_weight": draw(st.floats(0.0, 0.1)),
        "extrapolate": draw(st.floats(0.0, 1.0)),
        "amplitude_range": draw(st.floats(1.0, 2.0)),
    }


# -- core blocks ------------------------------------------------------------------------------------------

register(
    Constant,
    st.one_of(
        st.builds(Constant, finite, unit=st.sampled_from(["1", "mm"])),
        st.builds(Constant, st.floats(0.0, 6.28), unit=st.just("rad"), wrapped=st.just(True)),
        SHAPES.map(lambda s: Constant(np.arange(math.prod(s), dtype=float).reshape(s))),
    ),
)


@st.composite
def gain(draw):
    if draw(st.booleans()):
        shape = draw(SHAPES)
        k = draw(st.floats(-5, 5))
        return fed_as(Gain(k if draw(st.booleans()) else np.full(shape, k)), shape)
    rng = np.random.default_rng(draw(seeds))
    m, n = draw(st.integers(1, 4)), draw(st.integers(1, 4))
    return fed_as(Gain(rng.normal(size=(m, n)), matrix=True), (n,))


# stateless element-wise blocks: "a non-finite input element gives a non-finite output element"
PASSES = Policy(nonfinite={"y": lambda ins, seen: any(bad(v) for v in ins.values())})
register(Gain, gain(), lambda b: {"u": floats(b.test_shape)}, ["u"], PASSES)
register(
    Sum,
    generic(st.builds(Sum, st.text("+-", min_size=1, max_size=4))),
    lambda b: {f"u{i}": floats(b.test_shape) for i in range(len(b.signs))},
    ["*"],
    PASSES,
)


def _shifted(block, k, ins, outs, previous, seen):
    """UnitDelay's policy: the output is exactly the previous tick's input, bad or not."""
    expected = block._initial if k == 0 else seen[-2]["u"]
    assert np.array_equal(outs["y"], np.broadcast_to(expected, np.shape(outs["y"])), equal_nan=True), (
        f"UnitDelay.y = {outs['y']!r} at tick {k}, expected {expected!r}"
    )


register(
    UnitDelay,
    generic(st.builds(UnitDelay, finite)),
    lambda b: {"u": floats(b.test_shape)},
    ["u"],
    # "a pure shift": a non-finite sample comes out one tick later, unchanged
    Policy(nonfinite={"y": lambda ins, seen: len(seen) > 1 and bad(seen[-2]["u"])}, check=_shifted),
)
register(Integrator, generic(st.builds(Integrator, finite)), lambda b: {"u": floats(b.test_shape, "mm/s")}, ["u"])
register(
    Saturation,
    generic(st.tuples(finite, st.floats(0, 500)).map(lambda lw: Saturation(lw[0], lw[0] + lw[1]))),
    lambda b: {"u": floats(b.test_shape)},
    ["u"],
    # "NaN passes through as NaN"; an infinite sample is clipped like any other
    Policy(nonfinite={"y": lambda ins, seen: bool(np.isnan(ins["u"]).any())}),
)
register(
    LowPass,
    generic(st.builds(LowPass, st.floats(0.5, 40.0), st.integers(1, 6), init=st.sampled_from(["first", "zero"]))),
    lambda b: {"u": floats(b.test_shape)},
    ["u"],
    # "a sample with NaN or inf is skipped; the output holds its last value"
    Policy(holds={"y": input_bad("u")}),
)


def safe(u):
    """A callable that is itself safe on bad data, so that only Function's own handling is tested."""
    return np.tanh(np.nan_to_num(u, nan=0.0))


def check_function(block, k, ins, outs, previous, seen):
    assert outs["y"] == safe(ins["u"]), f"Function output {outs['y']} is not fn({ins['u']})"


register(
    Function,
    st.builds(lambda ft: Function(safe, inputs={"u": Signal()}, outputs=Signal(), feedthrough=ft), st.booleans()),
    lambda b: {"u": floats(())},
    ["u"],
    # Function outputs what its callable returns
    Policy(check=check_function),
)


@st.composite
def playback(draw):
    rng = np.random.default_rng(draw(seeds))
    data = 100 * rng.normal(size=(draw(st.integers(1, 30)), *draw(SHAPES)))
    data[rng.random(len(data)) < 0.2] = np.nan  # "NaN rows are played as they are"
    return Playback(data, at_end=draw(st.sampled_from(["hold", "repeat", "zero", "error"])))


def check_playback(block, k, ins, outs, previous, seen):
    n = len(block.data)
    if k < n or block.at_end == "hold":
        row = block.data[min(k, n - 1)]
    elif block.at_end == "repeat":
        row = block.data[k % n]
    else:
        row = np.zeros_like(block.data[0])
    assert np.array_equal(outs["y"], row, equal_nan=True), f"Playback played {outs['y']} at tick {k}, not {row}"


register(
    Playback,
    playback(),
    # its NaN rows come out as they are (checked exactly); at_end="error" raises SimulationError
    policy=Policy(
        nonfinite={"y": lambda ins, seen: True},
        check=check_playback,
        raises=(SimulationError,),
        raises_when=lambda block, k, exc: block.at_end == "error" and k >= len(block.data) and "at_end" in str(exc),
    ),
)
register(Probe, generic(st.builds(Probe)), lambda b: {"u": floats(b.test_shape)}, ["u"])
register(Mux, st.builds(Mux, st.integers(1, 4)), lambda b: {f"u{i}": floats(()) for i in range(b.n)}, ["*"], PASSES)
register(
    Demux,
    st.builds(Demux, st.integers(1, 4)),
    lambda b: {"u": floats((b.n,))},
    ["u"],
    Policy(nonfinite={f"y{i}": lambda ins, seen: bad(ins["u"]) for i in range(4)}),
)
register(
    Select,
    st.integers(1, 4).flatmap(lambda n: st.builds(Select, st.integers(0, n - 1)).map(lambda b: fed_as(b, (n,)))),
    lambda b: {"u": floats(b.test_shape)},
    ["u"],
    PASSES,
)
register(
    Substitute,
    st.integers(1, 4).flatmap(lambda n: st.builds(Substitute, st.integers(0, n - 1)).map(lambda b: fed_as(b, (n,)))),
    lambda b: {"u": floats(b.test_shape), "v": floats(())},
    ["u", "v"],
    PASSES,
)


@st.composite
def discrete_lti(draw):
    import control

    rng = np.random.default_rng(draw(seeds))
    n, m, p = draw(st.integers(1, 3)), draw(st.integers(1, 2)), draw(st.integers(1, 2))
    a = rng.standard_normal((n, n))
    a *= 0.9 / max(1e-9, float(np.abs(np.linalg.eigvals(a)).max()))  # stable
    d = rng.standard_normal((p, m)) if draw(st.booleans()) else np.zeros((p, m))
    b, c = rng.standard_normal((n, m)), rng.standard_normal((p, n))
    sys = control.ss(a, b, c, d, draw(st.sampled_from([0.01, True])))
    return DiscreteLTI(sys, rng.standard_normal(n))


register(DiscreteLTI, discrete_lti(), lambda b: {"u": floats(() if b.B.shape[1] == 1 else (b.B.shape[1],))}, ["u"])

# -- Social Connectedness ---------------------------------------------------------------------------------


@st.composite
def kuramoto_group(draw):
    n = draw(st.integers(2, 6))
    rng = np.random.default_rng(draw(seeds))
    return KuramotoGroup(
        rng.uniform(0.5, 5.0, n),
        draw(st.floats(0.0, 3.0)),
        adjacency="ring" if draw(st.booleans()) else (rng.random((n, n)) < 0.5).astype(float),
        assisted=draw(st.none() | st.integers(0, n - 1)),
        theta0=rng.uniform(0, TWO_PI, n),
        noise=draw(st.sampled_from([0.0, 0.3])),  # the noisy plant keeps the same bad-data policy
        drift_spread=draw(st.sampled_from([0.0, 0.1])),
        seed=draw(seeds),
    )


register(
    KuramotoGroup,
    kuramoto_group(),
    lambda b: (
        {"omega": floats((b.n,), "rad/s", scale=2.0, offset=3.0)}
        | ({"theta_l2": phase()} if b.assisted is not None else {})
    ),
    ["omega", "theta_l2"],
)
register(
    KuramotoOscillator,
    st.builds(KuramotoOscillator, st.floats(0.5, 5.0), st.floats(0, 3), st.integers(1, 3), theta0=st.floats(0, 6.28)),
    lambda b: {name: phase() for name in b.inputs},
    ["*"],
)


def check_order(block, k, ins, outs, previous, seen):
    """r is the order parameter of the finite phases alone, in [0, 1]."""
    theta = np.asarray(ins["theta"])
    ok = np.isfinite(theta)
    if ok.any():
        expected = abs(np.exp(1j * theta[ok]).mean())
        assert outs["r"] == pytest.approx(expected, abs=1e-9), f"r = {outs['r']}, expected {expected} on {theta}"


register(
    OrderParameter,
    generic(st.builds(OrderParameter), st.integers(1, 6).map(lambda n: (n,))),
    lambda b: {"theta": phase(b.test_shape)},
    ["theta"],
    # "non-finite phases are left out of the mean; with no finite phase the output holds"
    Policy(holds={"r": lambda block, ins, seen: not np.isfinite(ins["theta"]).any()}, check=check_order),
)
register(
    ArmPositions,
    st.builds(ArmPositions, st.integers(1, 5), st.floats(1.0, 300.0), finite, noise_std=st.floats(0, 5), seed=seeds),
    lambda b: {"theta": phase((b.n,))},
    ["theta"],
    Policy(nonfinite={"p": lambda ins, seen: bad(ins["theta"])}),
)


@st.composite
def stable_blender(draw):
    from cogblocks.sync import check_blender

    lam_min = draw(st.floats(0.05, 1.0))
    kw = {
        "lam_min": lam_min,
        "lam_max": lam_min + draw(st.floats(0.0, 2.0)),
        "e_max": draw(st.floats(0.05, 2.0)),
        "kappa_plus": draw(st.floats(0.1, 60.0)),
        "kappa_minus": draw(st.floats(0.1, 60.0)),
        "saturation": draw(st.sampled_from(["hard", "smooth"])),
        "psi": draw(st.sampled_from(["triangular", "bump"])),
    }
    # a valid instance compiles at 10 ms without a warning: its λ dynamics are stable and monotone
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        try:
            check_blender(Blender(**kw), 0.01)
        except (ValueError, RuntimeWarning):
            kw.update(kappa_plus=1.0, kappa_minus=2.5, e_max=max(kw["e_max"], 0.5))
    return Blender(**kw)


def check_blender_ref(block, k, ins, outs, previous, seen):
    """A non-finite θ_ref gives no alteration: θ_L2 = θ_L0."""
    l0, ref = float(ins["theta_l0"]), float(ins["theta_ref"])
    if math.isfinite(l0) and not math.isfinite(ref):
        assert outs["theta_l2"] == pytest.approx(l0 % TWO_PI, abs=1e-12), f"θ_ref = {ref} altered θ_L0 = {l0}"


register(
    Blender,
    stable_blender(),
    lambda b: {"theta_l0": phase(), "theta_ref": phase()},
    ["theta_l0", "theta_ref"],
    # "a non-finite theta_l0 holds the last outputs and does not advance λ; a non-finite theta_ref
    # gives no alteration (θ_L2 = θ_L0) for that tick"
    Policy(holds={"theta_l2": input_bad("theta_l0"), "lam": input_bad("theta_l0")}, check=check_blender_ref),
)


def no_other_phase(block, ins, seen):
    return not np.isfinite(np.asarray(ins["theta"])[block.others]).any()


register(
    MeanPhaseMotion,
    st.integers(2, 6).flatmap(lambda n: st.builds(MeanPhaseMotion, st.just(n), st.integers(0, n - 1))),
    lambda b: {"theta": phase((len(b.others) + 1,)), "lam": floats((), "rad", scale=1.0, offset=1.0)},
    ["theta", "lam"],
    # "non-finite phases are left out; with none left the output holds"
    Policy(holds={"theta_ref": no_other_phase}),
)


class FixedPolicy:
    """An L3 policy that always picks the same action."""

    def __init__(self, action: int) -> None:
        self.action = action

    def reset(self, omega_init: float) -> None:
        pass

    def act(self, context) -> int:
        # OscillatorMotion's policy: a policy only ever sees finite contexts
        assert np.isfinite(context.theta).all() and math.isfinite(context.lam), f"non-finite context {context}"
        return self.action


@st.composite
def motion_computer(draw):
    n = draw(st.integers(2, 6))
    return OscillatorMotion(
        FixedPolicy(draw(st.integers(0, 10))),
        n=n,
        assisted=draw(st.integers(0, n - 1)),
        gain=draw(st.floats(0.0, 3.0)),
        omega_init=draw(st.floats(-15.0, 15.0)),
    )


register(
    OscillatorMotion,
    motion_computer(),
    lambda b: {"theta": phase((len(b.others) + 1,)), "lam": floats((), "rad", scale=1.0, offset=1.0)},
    ["theta", "lam"],
)


def check_l2_sync(block, k, ins, outs, previous, seen):
    """theta_l0 is the assisted participant's phase exactly as given."""
    given = ins["theta"][block["motion"].assisted]
    assert np.array_equal(outs["theta_l0"], given, equal_nan=True), f"theta_l0 = {outs['theta_l0']}, given {given}"


@st.composite
def l2_sync(draw):
    from cogblocks.sync import L2Sync

    if draw(st.booleans()):
        motion = draw(motion_computer())
    else:
        n = draw(st.integers(2, 6))
        motion = MeanPhaseMotion(n, draw(st.integers(0, n - 1)))
    return L2Sync(motion, motion.assisted, blender=draw(st.none() | stable_blender()))


@st.composite
def motion_role(draw):
    n = draw(st.integers(2, 6))
    return MotionComputer(n, draw(st.integers(0, n - 1)))


register(
    MotionComputer,
    motion_role(),
    lambda b: {"theta": phase((b.n,)), "lam": floats((), "rad", scale=1.0, offset=1.0)},
    ["theta", "lam"],
)


def flags(n: int) -> Feed:
    return Feed(
        Signal(shape=(n,), dtype=bool),
        lambda ticks, _: st.lists(st.lists(st.booleans(), min_size=n, max_size=n), min_size=ticks, max_size=ticks).map(
            lambda rows: np.array(rows, dtype=bool)
        ),
        False,
    )


def check_handover(block, k, ins, outs, previous, seen):
    """Until the assisted participant's estimate has settled (on a tick it could act on), the avatar is the person."""
    usable = [past for past in seen if not bad(past["theta"][block.assisted]) and not bad(past["theta_l2"])]
    if usable and usable[-1] is ins and not any(past["settled"][block.assisted] for past in usable):
        assert outs["theta_avatar"] == ins["theta"][block.assisted] % TWO_PI


def held_input(block, ins, seen):
    return bad(ins["theta_l2"]) or bad(ins["theta"][block.assisted])


register(
    SettledHandover,
    st.integers(1, 5).flatmap(
        lambda n: st.builds(SettledHandover, st.just(n), st.integers(0, n - 1), slew=st.floats(0.5, 20.0))
    ),
    lambda b: {"theta": phase((b.n,)), "theta_l2": phase(()), "settled": flags(b.n)},
    ["theta", "theta_l2"],
    Policy(holds={"theta_avatar": held_input}, check=check_handover),
)


def register_l2_sync() -> None:
    from cogblocks.sync import L2Sync

    register(
        L2Sync,
        l2_sync(),
        lambda b: {"theta": phase((b["motion"].n,))},
        ["theta"],
        # "a non-finite phase never reaches theta_l2, theta_ref or lam; theta_l0 (the phase as given) shows it"
        Policy(
            nonfinite={"theta_l0": when_bad("theta")},
            outside={"theta_l0": lambda ins, seen: True},  # as given: check_l2_sync asserts it is the input
            check=check_l2_sync,
        ),
    )


register_l2_sync()


def register_mpc() -> None:
    from cogblocks.sync import GroupIdentifier, MPCMotion, PacingMotion, RecedingPlanMotion
    from cogblocks.sync.guarded import GuardedPacingMotion
    from cogblocks.sync.pacing import PACE
    from cogblocks.sync.planned import PlannedMotion

    def planned(*args: Any, **kwargs: Any) -> PlannedMotion:
        with warnings.catch_warnings():  # the retired class, still checked for its release
            warnings.simplefilter("ignore", DeprecationWarning)
            return PlannedMotion(*args, **kwargs)

    # one small problem (a single cached casadi build) whatever hypothesis draws
    register(
        MPCMotion,
        st.just(None).map(
            lambda _: MPCMotion(3, 1, decide_every=0.05, knots=2, step=0.05, candidates=3, time_limit_ms=20.0)
        ),
        lambda b: {"theta": phase((3,)), "lam": floats((), "rad", scale=1.0, offset=1.0)},
        ["theta", "lam"],
    )
    # "a bad tick identifies and decides nothing; θ_ref holds, or keeps integrating the paced frequency"
    register(
        PacingMotion,
        st.integers(2, 5).flatmap(
            lambda n: st.builds(
                PacingMotion,
                st.just(n),
                st.integers(0, n - 1),
                decide_every=st.sampled_from([0.01, 0.02, 0.03, 0.05]),
                horizon=st.just(0.2),
                min_ticks=st.integers(1, 3),
                min_excitation=st.just(0.0),
                start=st.sampled_from(["none", "mean"]),
            )
        ),
        lambda b: {"theta": phase((b.n,)), "lam": floats((), "rad", scale=1.0, offset=1.0)},
        ["theta", "lam"],
        Policy(holds={"theta_ref": lambda b, ins, seen: b.mode != PACE and not _usable(ins)}),
    )
    # "a bad tick identifies nothing; θ_ref holds, or keeps integrating the paced frequency"
    register(
        GuardedPacingMotion,
        st.integers(2, 5).flatmap(
            lambda n: st.builds(
                GuardedPacingMotion,
                st.just(n),
                st.integers(0, n - 1),
                decide_every=st.sampled_from([0.01, 0.02, 0.03, 0.05]),
                horizon=st.just(0.2),
                min_ticks=st.integers(1, 3),
                min_excitation=st.just(0.0),
                start=st.sampled_from(["none", "mean"]),
                fallback=st.sampled_from(["none", "mean"]),
            )
        ),
        lambda b: {"theta": phase((b.n,)), "lam": floats((), "rad", scale=1.0, offset=1.0)},
        ["theta", "lam"],
        Policy(holds={"theta_ref": lambda b, ins, seen: b.mode != PACE and not _usable(ins)}),
    )
    # "a bad tick identifies or plans nothing; θ_ref holds" (no window sweep: the rule starts alone keep it cheap)
    register(
        PlannedMotion,
        st.integers(2, 5).flatmap(
            lambda n: st.builds(
                planned,
                st.just(n),
                st.integers(0, n - 1),
                end=st.floats(0.05, 0.3),
                sweeps=st.just(()),
                min_ticks=st.integers(1, 3),
                min_excitation=st.just(0.0),
            )
        ),
        lambda b: {"theta": phase((b.n,)), "lam": floats((), "rad", scale=1.0, offset=1.0)},
        ["theta", "lam"],
        Policy(holds={"theta_ref": lambda b, ins, seen: not _usable(ins)}),
    )
    register(
        RecedingPlanMotion,
        st.integers(2, 5).flatmap(
            lambda n: st.builds(
                RecedingPlanMotion,
                st.just(n),
                st.integers(0, n - 1),
                end=st.floats(0.05, 0.3),
                decide_every=st.sampled_from([0.01, 0.02]),
                horizon=st.just(0.05),
                sweeps=st.just(()),
                min_ticks=st.integers(1, 3),
                min_excitation=st.just(0.0),
            )
        ),
        lambda b: {"theta": phase((b.n,)), "lam": floats((), "rad", scale=1.0, offset=1.0)},
        ["theta", "lam"],
        Policy(holds={"theta_ref": lambda b, ins, seen: not _usable(ins)}),
    )
    register(
        GroupIdentifier,
        st.integers(2, 6).flatmap(
            lambda n: st.builds(GroupIdentifier, st.just(n), assisted=st.none() | st.integers(0, n - 1))
        ),
        lambda b: {"theta": phase((b.n,))} | ({"theta_l2": phase()} if b.assisted is not None else {}),
        ["theta"],
        # "a tick with a bad phase adds no equation (nor the tick after); the outputs hold their last estimate"
        Policy(holds={"omega": lambda b, ins, seen: not _usable(ins), "gain": lambda b, ins, seen: not _usable(ins)}),
    )


def _usable(ins) -> bool:
    from cogblocks.sync.identification import usable_phases

    return usable_phases(np.asarray(ins["theta"])) and usable_phases(np.asarray(ins.get("theta_l2", 0.0)))


register_mpc()


def register_shielded() -> None:
    from cogblocks.sync import ShieldedMotion
    from cogblocks.sync.shielded import FOLLOW

    # "doing nothing, θ_ref holds on a bad tick; following, it is the oscillator's phase (which coasts)"
    register(
        ShieldedMotion,
        motion_computer().flatmap(
            lambda m: st.builds(
                ShieldedMotion,
                st.just(m),
                decide_every=st.sampled_from([0.01, 0.02, 0.03, 0.05]),
                horizon=st.sampled_from([0.01, 0.05]),
                margin=st.sampled_from([0.0, 0.005]),
                min_ticks=st.integers(1, 3),
                min_excitation=st.just(0.0),
            )
        ),
        lambda b: {"theta": phase((b.n,)), "lam": floats((), "rad", scale=1.0, offset=1.0)},
        ["theta", "lam"],
        Policy(holds={"theta_ref": lambda b, ins, seen: b.mode != FOLLOW and not _usable(ins)}),
    )


register_shielded()


@st.composite
def gated_motion(draw):
    from cogblocks.sync import GatedMotion
    from cogblocks.sync.gated import FALLBACKS

    if draw(st.booleans()):
        model = draw(motion_computer())
    else:
        n = draw(st.integers(2, 6))
        model = MeanPhaseMotion(n, draw(st.integers(0, n - 1)))
    return GatedMotion(
        model,
        adjacency="ring",
        fallback=draw(st.sampled_from(FALLBACKS)),
        decide_after=draw(st.sampled_from([0.01, 0.05])),
        check_every=draw(st.sampled_from([0.01, 0.03])),
        threshold=draw(st.sampled_from([0.0, 0.02])),
    )


def register_gated() -> None:
    from cogblocks.sync import GatedMotion

    # "that of the blocks inside": the gate holds θ_ref on a non-finite reference, the models never emit one
    register(
        GatedMotion,
        gated_motion(),
        lambda b: {"theta": phase((b.n,)), "lam": floats((), "rad", scale=1.0, offset=1.0)},
        ["theta", "lam"],
    )


register_gated()

# -- sensor streams and L1 ----------------------------------------------------------------------------------

POSITION_SHAPES = st.sampled_from([(), (1,), (3,)])


def check_kalman(block, k, ins, outs, previous, seen):
    """A missing sample (any non-finite component) is predicted."""
    if bad(ins["p"]):
        assert outs["predicted"], f"KalmanEstimator did not flag the missing sample {ins['p']} as predicted"


register(
    KalmanEstimator,
    generic(kalman(), POSITION_SHAPES),
    lambda b: {"p": floats(b.test_shape, "mm", scale=150.0, offset=300.0)},
    ["p"],
    # "before any usable sample the outputs are NaN" (beyond 1e9 is missing, like NaN); missing, frozen and
    # rejected frames are predicted
    Policy(nonfinite={out: until_usable("p") for out in ("p_hat", "v_hat", "a_hat")}, check=check_kalman),
)
register(
    RestGate,
    generic(st.builds(RestGate, st.floats(0.0, 200.0))),
    lambda b: {"u": floats(b.test_shape, "mm/s")},
    ["u"],
    # "a sample with a non-finite element passes unchanged"
    PASSES,
)
register(
    L1,
    generic(
        st.builds(L1, st.floats(0.0, 0.3), smoothing=st.booleans(), estimator=st.none() | kalman()), POSITION_SHAPES
    ),
    lambda b: {"p": floats(b.test_shape, "mm", scale=150.0, offset=300.0)},
    ["p"],
    # "the output is NaN only before the first sample the estimator can use (finite, below 1e9)"
    Policy(nonfinite={"p_avatar": until_usable("p")}),
)


def couple_predictor(block, streams):
    """The estimator flags every missing sample as predicted."""
    missing = np.array([bad(p) for p in streams["p"]])
    return dict(streams, predicted=streams["predicted"] | missing)


register(
    KinematicPredictor,
    generic(st.builds(KinematicPredictor, st.floats(0.0, 0.5), smoothing=st.booleans()), POSITION_SHAPES),
    lambda b: {
        "p": floats(b.test_shape, "mm"),
        "p_hat": floats(b.test_shape, "mm"),
        "v_hat": floats(b.test_shape, "mm/s"),
        "a_hat": floats(b.test_shape, "mm/s^2"),
        "predicted": bools(),
    },
    ["p", "p_hat", "v_hat", "a_hat"],
    # the estimates are NaN before the estimator's first sample and that passes (L1's policy); a bad
    # measurement is flagged as predicted and must not reach the output
    Policy(nonfinite={"p_out": when_bad("p_hat", "v_hat", "a_hat")}),
    couple_predictor,
)

# -- 1D phase -----------------------------------------------------------------------------------------------


def couple_algorithm1(block, streams):
    """``p`` is the low-passed ``raw``: the LowPass in front holds on bad samples (and is 0 before any)."""
    raw, p = streams["raw"], streams["p"].copy()
    last = 0.0
    for k in range(len(raw)):
        if math.isfinite(raw[k]) and math.isfinite(p[k]):
            last = p[k]
        p[k] = last
    return dict(streams, p=p)


register(
    Algorithm1Phase,
    st.builds(Algorithm1Phase, cutoff=st.none() | st.floats(0.5, 10.0), **ALGORITHM1),
    lambda b: {"p": floats((), "mm", scale=150.0), "raw": floats((), "mm", scale=150.0)},
    ["raw"],  # p is the filtered raw signal: couple_algorithm1 derives it
    # "a missing sample (NaN or inf raw) advances no state: theta is extrapolated, held is True, amplitudes
    # hold"; the phase is "never NaN"
    Policy(holds={out: input_bad("raw") for out in ("amp_p", "amp_v")}, check=flags_held("raw")),
    couple_algorithm1,
)
register(
    PhaseEstimator,
    st.builds(
        PhaseEstimator,
        cutoff=st.floats(0.5, 10.0),
        compensate=st.booleans(),
        front_end=st.sampled_from(["lowpass", "kalman"]),
        **ALGORITHM1,
    ),
    lambda b: {"p": floats((), "mm", scale=150.0, offset=300.0)},
    ["p"],
    # Algorithm1Phase's policy
    Policy(holds={out: input_bad("p") for out in ("amp_p", "amp_v")}, check=flags_held("p")),
)

# -- 3D phase -----------------------------------------------------------------------------------------------

register(
    BackwardDifference,
    generic(st.builds(BackwardDifference)),
    lambda b: {"u": floats(b.test_shape, "mm")},
    ["u"],
    # "a non-finite sample gives a non-finite output and is not remembered"
    Policy(nonfinite={"y": when_bad("u")}),
)
register(
    PeriodEstimator,
    st.composite(lambda draw: PeriodEstimator(**period_kwargs(draw)))(),
    lambda b: {"p": floats((3,), "mm", scale=150.0), "theta": phase(), "valid": bools()},
    ["p", "theta"],
    # "a sample with a non-finite coordinate is skipped"
)
register(
    ReferenceCustomizer,
    st.tuples(st.builds(ReferenceCustomizer, curve()), st.integers(4, 40)).map(lambda bc: fed_as(bc[0], (bc[1], 3))),
    lambda b: {
        "last_period": floats(b.test_shape, "mm", scale=150.0),
        "last_phases": floats(b.test_shape[:1], "rad", scale=3.0, offset=3.0),
        "last_length": ints(lambda n: int_list(n, 2, b.test_shape[0])),
        "last_duration": floats((), "s", scale=1.0, offset=2.0),
        "period_count": ints(counter),
    },
    ["last_period", "last_phases", "last_duration"],
)


def check_held_at_zero(block, k, ins, outs, previous, seen):
    """θ is held at 0 while ``valid`` is False (no customised reference yet)."""
    if not outs["valid"]:
        assert outs["theta"] == 0.0, f"θ = {outs['theta']} while not valid"


def couple_phase_computer(block, streams):
    """The reference's length never exceeds the capacity of its arrays."""
    return dict(streams, length=np.minimum(streams["length"], block.test_shape[0]))


register(
    PhaseComputer,
    st.composite(lambda draw: fed_as(PhaseComputer(**search_kwargs(draw)), (draw(st.integers(2, 40)), 3)))(),
    lambda b: {
        "p": floats((3,), "mm", scale=150.0),
        "v": floats((3,), "mm/s", scale=500.0),
        "positions": floats(b.test_shape, "mm", scale=150.0),
        "velocities": floats(b.test_shape, "mm/s", scale=500.0),
        "length": ints(lambda n: int_list(n, 2, 40)),
        "count": ints(counter),
        "duration": floats((), "s", scale=1.0, offset=2.0),
    },
    ["p", "v", "positions", "velocities"],
    # "a tick with a non-finite position or velocity holds the last phase"
    Policy(holds={out: input_bad("p", "v") for out in ("theta", "valid")}, check=check_held_at_zero),
    couple_phase_computer,
)
register(
    PhaseEstimator3D,
    st.composite(
        lambda draw: PhaseEstimator3D(
            draw(curve()),
            velocity=draw(st.sampled_from(["difference", "kalman"])),
            **period_kwargs(draw),
            **search_kwargs(draw),
        )
    )(),
    lambda b: {"p": floats((3,), "mm", scale=150.0)},
    ["p"],
    # a bad sample gives a bad velocity inside, on which the phase computer holds (checked on its own)
    Policy(check=check_held_at_zero),
)


def selected_sample(block, ins):
    """The reference sample the phase selects: index round(N θ / 2π) mod N, halves up."""
    n = block.n_samples
    return ins["reference"][math.floor(n * float(ins["theta"]) / TWO_PI + 0.5) % n]


register(
    PhasePositionComputer,
    st.builds(PhasePositionComputer, curve(min_size=1), noise_std=st.floats(0.0, 5.0), seed=seeds),
    lambda b: {"theta": phase(), "reference": floats((b.n_samples, 3), "mm", scale=150.0)},
    ["theta", "reference"],
    # "a non-finite phase, or a non-finite element in the reference sample it selects, holds the last position"
    Policy(holds={"p": lambda block, ins, seen: bad(ins["theta"]) or bad(selected_sample(block, ins))}),
)

# -- PoP of Amplification (modules being written: registered when they import) -----------------------------


def check_velocity_blender(block, k, ins, outs, previous, seen):
    """v_a is non-finite only where the policy lets a bad input through; v_r has no say while c = 1."""
    if not bad(outs["v_a"]):
        return
    assert bad(ins["v_h"]) or bad(ins["v_u"]) or outs["c"] < 1.0, (
        f"VelocityBlender.v_a = {outs['v_a']!r} with c = {outs['c']} from a bad v_r alone, at tick {k} on {ins}"
    )


def check_l2_amplification(block, k, ins, outs, previous, seen):
    """The altered position stays a position a hand can have, whatever the human samples."""
    assert usable(outs["p_a"]), f"L2Amplification.p_a = {outs['p_a']} at tick {k} on {ins}"


def check_optimal_blender(block, k, ins, outs, previous, seen):
    """What later plans are built on stays usable; v_r makes v_a non-finite only where it has weight."""
    t = k // block.every
    if t < len(block.human):
        assert usable(block.human[t]) and usable(block.altered[t]), f"OptimalBlender recorded a bad sample at {t}"
    if bad(outs["v_a"]) and not (bad(ins["v_h"]) or bad(ins["v_u"])):
        assert block.end == 0 and outs["c"] < 1.0, f"OptimalBlender.v_a = {outs['v_a']} from a bad v_r alone"


def check_classifier(block, k, ins, outs, previous, seen):
    """ε̂ is NaN exactly while nothing is classified ("NaN until the movement has started"), else in [0, 1]."""
    if outs["length"] > 0:
        assert 0.0 <= outs["eps"] <= 1.0, f"ε̂ = {outs['eps']} with {outs['length']} samples classified"
    else:
        assert math.isnan(outs["eps"]), f"ε̂ = {outs['eps']} before the movement started"


# A hand neither sits nor moves a kilometre (per second) away: the Amplification blocks' bound of a good sample.
KILOMETRE_MM = 1e6


def usable(value) -> bool:
    """Whether a sample is finite and below a kilometre (per second) in every element."""
    value = np.asarray(value, dtype=float)
    return bool(np.isfinite(value).all() and (np.abs(value) < KILOMETRE_MM).all())


def check_classifier_holds(block, k, ins, outs, previous, seen):
    """A window with a sample that is not usable is not classified: every output holds."""
    from cogblocks.amplification.buffer import ordered_window

    check_classifier(block, k, ins, outs, previous, seen)
    if not usable(ordered_window(ins["velocity"], int(ins["count"]))):
        for name in ("eps", "decision", "length"):
            assert np.array_equal(outs[name], previous[name], equal_nan=True), (
                f"EncoderClassifier.{name} = {outs[name]} does not hold {previous[name]} on a bad window at tick {k}"
            )


def check_projector(block, k, ins, outs, previous, seen):
    """The running distances stay finite whatever the samples (bad ones count as the bound)."""
    assert np.isfinite(block.sums).all(), f"LibraryProjector sums {block.sums} at tick {k}"


def check_corrector(block, k, ins, outs, previous, seen):
    """v_u = gain · α · (p_h − p_a) of the last usable positions; α changes only on a usable decision tick."""
    if k == 0:
        return
    before = seen[:-1]
    gaps = [i["p_h"] - i["p_a"] for i in before if usable(i["p_h"]) and usable(i["p_a"])]
    gap = gaps[-1] if gaps else np.zeros(3)
    np.testing.assert_allclose(outs["v_u"], block.gain * outs["alpha"] * gap, rtol=1e-12, atol=0.0)
    last = before[-1]
    decided = k % block.interval == 0 and all(usable(last[n]) for n in ("p_h", "p_a", "v_h", "v_a"))
    if not decided:
        assert np.array_equal(outs["alpha"], previous["alpha"]), f"α changed at tick {k} without a usable decision"


def check_buffer(block, k, ins, outs, previous, seen):
    """The newest row holds this tick's sample, or the last usable one (zeros before any)."""
    row = k % block.capacity
    for ring, name in (("velocity", "v"), ("position", "p")):
        good = [past[name] for past in seen if usable(past[name])]
        expected = good[-1] if good else np.zeros(3)
        assert np.array_equal(outs[ring][row], expected), f"Buffer stored {outs[ring][row]} for {ins[name]}"
    assert outs["count"] == k + 1 and outs["length"] == min(k + 1, block.capacity)


def register_amplification() -> None:
    import torch

    import cogblocks.amplification as amp
    from cogblocks.data.reach import generate_reach_library

    library = generate_reach_library(1, n_subjects=2, n_fear=5, n_no_fear=6)
    torch.manual_seed(0)
    network = amp.EncoderNet(hidden=8).double().eval()
    table = amp.solution_table(network, library, cache_dir=None)
    corrector = amp.load_corrector()

    def buffer_count(n):  # the buffer's count: one more sample every tick
        return st.just(np.arange(1, n + 1, dtype=np.int64))

    register(
        amp.Buffer,
        st.builds(amp.Buffer, st.integers(1, 30)),
        lambda b: {"v": floats((3,), "mm/s", scale=500.0), "p": floats((3,), "mm", scale=150.0)},
        ["v", "p"],
        # "a sample with a non-finite or implausible element is stored as the last good one (zeros before any)"
        Policy(check=check_buffer),
    )
    register(
        amp.EncoderClassifier,
        generic(
            st.builds(amp.EncoderClassifier, st.just(network), rest_speed=st.floats(0.0, 10.0)),
            st.integers(1, 40).map(lambda c: (c, 3)),
        ),
        lambda b: {"velocity": floats(b.test_shape, "mm/s", scale=500.0), "count": ints(buffer_count)},
        ["velocity"],
        # "a window holding a sample beyond 1 km/s is not classified and the outputs hold"
        Policy(nonfinite={"eps": lambda ins, seen: True}, check=check_classifier_holds),
    )

    @st.composite
    def projector(draw):
        block = amp.LibraryProjector(
            library,
            e_des=draw(st.sampled_from([0, 1])),
            interval=draw(st.integers(1, 10)),
            metric=draw(st.sampled_from(["mean", "l2"])),
            dtype=draw(st.sampled_from(["float32", "float64"])),
        )
        return fed_as(block, (draw(st.integers(block.interval, 40)), 3))

    register(
        amp.LibraryProjector,
        projector(),
        lambda b: {"velocity": floats(b.test_shape, "mm/s", scale=500.0), "count": ints(buffer_count)},
        ["velocity"],
        # "an element beyond 1 km/s (NaN included) counts as that bound with its sign"
        Policy(check=check_projector),
    )

    def couple_velocity_blender(block, streams):
        """The projector's decision is a pair of w̃: nearest among its rows, reference among its columns."""
        rng = np.random.default_rng(int(streams["decisions"].sum()))
        n = len(streams["decisions"])
        return dict(streams, nearest=rng.choice(table.rows, n), reference=rng.choice(table.cols, n))

    zeros = ints(lambda n: st.just(np.zeros(n, np.int64)))

    def blending_feeds(block):  # the ports every blending rule shares
        return {
            "v_h": floats((3,), "mm/s", scale=500.0),
            "v_r": floats((3,), "mm/s", scale=500.0),
            "v_u": floats((3,), "mm/s", scale=50.0),
            "nearest": zeros,
            "reference": zeros,
            "decisions": ints(counter),
        }

    register(
        amp.VelocityBlender,
        st.builds(amp.VelocityBlender, st.just(table)),
        blending_feeds,
        ["v_h", "v_r", "v_u"],
        # "a non-finite v_h or v_u, or a non-finite v_r while it is weighted (c < 1), gives a non-finite v_a"
        Policy(nonfinite={"v_a": when_bad("v_h", "v_r", "v_u")}, check=check_velocity_blender),
        couple_velocity_blender,
    )
    register(
        amp.VelocityPositionComputer,
        st.builds(amp.VelocityPositionComputer),
        lambda b: {"v": floats((3,), "mm/s", scale=500.0), "p_start": floats((3,), "mm", scale=150.0)},
        ["v", "p_start"],
        # "a non-finite or implausible velocity holds the position; integration starts at the first p_start that
        # is finite and plausible"
        Policy(
            holds={"p": lambda block, ins, seen: not usable(ins["v"]) and any(usable(i["p_start"]) for i in seen[:-1])}
        ),
    )
    corrector_feeds = {
        "p_h": floats((3,), "mm", scale=150.0),
        "p_a": floats((3,), "mm", scale=150.0),
        "v_h": floats((3,), "mm/s", scale=500.0),
        "v_a": floats((3,), "mm/s", scale=500.0),
        "horizon": ints(lambda n: int_list(n, 0, 200)),
    }
    register(amp.NoCorrection, st.builds(amp.NoCorrection), lambda b: corrector_feeds, ["p_h", "p_a", "v_h", "v_a"])
    register(
        amp.RLCorrector,
        st.builds(amp.RLCorrector, st.just(corrector), gain=st.floats(0.1, 20.0), interval=st.integers(1, 10)),
        lambda b: corrector_feeds,
        ["p_h", "p_a", "v_h", "v_a"],
        # "a non-finite or implausible position keeps the last stored difference; such a state keeps the last action"
        Policy(check=check_corrector),
    )

    from cogblocks.amplification import L2Amplification, OptimalBlender

    # the casadi setting with one tick per decision (the class's defaults are the shipped linearised one)
    PLAIN = {
        k: st.just(v)
        for k, v in dict(
            solver="sqpmethod", solve_ticks=1, iterations=10, realism=30.0, margin=0.05, removal_margin=None,
            emit="human", guard_rest=False, neighbours=1, terminal_margin=5.0,
        ).items()
    }  # fmt: skip

    @st.composite
    def l2_amplification(draw):
        capacity = draw(st.integers(10, 60))
        corrector_block = draw(st.sampled_from([None, "rl"]))
        return L2Amplification(
            library,
            table,
            corrector=amp.RLCorrector(corrector) if corrector_block else None,
            interval=draw(st.integers(1, 10)),
            capacity=capacity,
        )

    register(
        L2Amplification,
        l2_amplification(),
        lambda b: {"v_h": floats((3,), "mm/s", scale=500.0), "p_h": floats((3,), "mm", scale=150.0)},
        ["v_h", "p_h"],
        # "the buffer stores a bad sample as the last good one; the blend passes a non-finite v_h to v_a on that
        # tick, and the position then holds"
        Policy(nonfinite={"v_a": when_bad("v_h")}, check=check_l2_amplification),
    )
    register(
        OptimalBlender,
        st.builds(
            OptimalBlender, st.just(library), st.just(network), st.just(table), time_limit_ms=st.just(50.0), **PLAIN
        ),
        blending_feeds,
        ["v_h", "v_r", "v_u"],
        # "a non-finite v_h or v_u gives a non-finite v_a on that tick (v_r only counts while the table's c < 1 is in
        # force); a non-finite or implausible sample is recorded as zero for later plans"
        Policy(nonfinite={"v_a": when_bad("v_h", "v_r", "v_u")}, check=check_optimal_blender),
        couple_velocity_blender,
    )


register_amplification()


# -- known violations: strict xfails, each one a report for the block's owner ------------------------------
# (block class, input) -> what is wrong; none is known. A strict xfail fails once the block is fixed, so the
# entry cannot outlive the defect.

VIOLATIONS: dict[tuple[type | None, str], str] = {}


# -- the tests ----------------------------------------------------------------------------------------------


def public_blocks() -> set[type]:
    return set(catalogue.public_blocks().values())


def test_every_public_block_has_a_factory():
    missing = sorted(f"{cls.__module__}.{cls.__name__}" for cls in public_blocks() if cls not in FACTORIES)
    assert not missing, f"public blocks without an entry in FACTORIES (add one, with its policy): {missing}"


def test_every_public_block_documents_its_bad_data_policy():
    silent = sorted(cls.__name__ for cls in public_blocks() if "Bad data policy" not in (inspect.getdoc(cls) or ""))
    assert not silent, f"public blocks whose docstring states no 'Bad data policy': {silent}"


def case_id(cls, target) -> str:
    return f"{cls.__module__.rsplit('.', 1)[-1]}.{cls.__name__}-{target or 'no_input'}"


def cases():
    for cls, fac in FACTORIES.items():
        for target in fac.targets or ("",):
            reason = VIOLATIONS.get((cls, target))
            marks = [pytest.mark.xfail(strict=True, reason=reason)] if reason else []
            yield pytest.param(cls, target, id=case_id(cls, target), marks=marks)


@pytest.mark.parametrize(("cls", "target"), list(cases()))
@ROBUST
@given(data=st.data())
def test_bad_data_policy(cls, target, data):
    fac = FACTORIES[cls]
    block = data.draw(fac.block, label="block")
    feeds = fac.feeds(block)
    assume(target in feeds or target in ("", "*"))  # KuramotoGroup has theta_l2 only when assisted
    n = data.draw(TICKS, label="ticks")
    streams = {}
    for name, feed in feeds.items():
        glitched = feed.samples and target in (name, "*")
        streams[name] = data.draw(feed.stream(n, ALL_GLITCHES if glitched else ()), label=name)
    if fac.couple is not None:
        streams = fac.couple(block, streams)
    drive(block, feeds, streams, n, fac.policy)


@pytest.mark.parametrize("cls", [pytest.param(cls, id=case_id(cls, "")) for cls, f in FACTORIES.items() if f.targets])
@settings(max_examples=3, deadline=None, derandomize=True, database=None)
@given(data=st.data())
def test_wrong_shape_is_refused_naming_the_input(cls, data):
    """A sample of the wrong shape fed to ``step`` raises ValueError naming the input, before any block runs."""
    fac = FACTORIES[cls]
    block = data.draw(fac.block, label="block")
    feeds = fac.feeds(block)
    assume(feeds)
    specs = {name: concrete(block.inputs[name], feed.spec) for name, feed in feeds.items()}
    d = Diagram()
    d.add("b", block)
    for name, spec in specs.items():
        d.expose_input(name, block.inputs[name], spec=spec)
    compiled = d.compile()
    good = {name: spec.zeros() for name, spec in specs.items()}
    name = data.draw(st.sampled_from(sorted(feeds)), label="input")
    shape = good[name].shape
    wrong = [(*shape, 2)] + ([(*shape[:-1], shape[-1] + 1)] if shape else [])
    for bad_shape in wrong:
        with pytest.raises(ValueError, match=rf"'{name}'.*{re.escape(str(shape))}"):
            compiled.step(**dict(good, **{name: np.ones(bad_shape)}))
        assert compiled.k == 0, "a refused input must not run the tick"


ENGINE = "engine: CompiledDiagram.set_inputs writes arr[...] = value"


@pytest.mark.parametrize(
    ("spec", "value", "expected"),
    [
        pytest.param(Signal(shape=(3,)), np.ones(4), r"shape \(3,\)", id="too-long"),
        pytest.param(Signal(shape=()), np.ones(2), r"shape \(\)", id="vector-into-scalar"),
        pytest.param(
            Signal(shape=(3,)),
            1.0,
            r"shape \(3,\)",
            id="scalar-into-vector",
        ),
        pytest.param(
            Signal(shape=(3,)),
            np.ones((1, 3)),
            r"shape \(3,\)",
            id="row-into-vector",
        ),
        pytest.param(
            Signal(dtype=np.int64),
            math.inf,
            "int64",
            id="inf-into-counter",
        ),
        pytest.param(
            Signal(dtype=np.int64),
            1e300,
            "int64",
            id="huge-into-counter",
        ),
        pytest.param(
            Signal(dtype=np.int64),
            math.nan,
            "int64",
            id="nan-into-counter",
        ),
        pytest.param(
            Signal(dtype=np.int64),
            2.7,
            "int64",
            id="fraction-into-counter",
        ),
    ],
)
def test_step_refuses_a_sample_that_does_not_fit(spec, value, expected):
    """``step`` raises ValueError naming the input and what it expects; nothing is broadcast or truncated."""
    d = Diagram()
    sink = d.add("sink", Probe())
    d.expose_input("u", sink.u, spec=spec)
    compiled = d.compile()
    with pytest.raises(ValueError, match=rf"'u'.*{expected}"):
        compiled.step(u=value)
