"""Engine benchmark: one Kuramoto network built four ways, timed in the same run.

N = 7, ring, gain 4.4/7, Table 2 group 3 frequencies, forward Euler at 10 ms for
300 s (30 001 ticks, t = 0 … 300 s), phases from 0, order parameter every tick.
The hand-written NumPy loop is the reference the others are divided by.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

import numpy as np

from cogblocks.blocks import Mux, Probe
from cogblocks.sim import Diagram, Simulator
from cogblocks.sync import KuramotoGroup, KuramotoOscillator, OrderParameter, ring_adjacency

OMEGA = np.array([2.7151, 2.9299, 4.0344, 2.1476, 3.9117, 3.7429, 3.2827])
GAIN = 4.4 / 7
DT = 0.01
TWO_PI = 2 * np.pi


def numpy_loop(n_steps: int) -> float:
    """The reference: a plain NumPy loop, order parameter logged every tick."""
    a = ring_adjacency(len(OMEGA))
    theta = np.zeros(len(OMEGA))
    r = np.empty(n_steps)
    n = len(OMEGA)
    for k in range(n_steps):
        r[k] = np.hypot(np.cos(theta).sum(), np.sin(theta).sum()) / n
        theta = np.mod(theta + DT * (OMEGA + GAIN * (a * np.sin(theta[None, :] - theta[:, None])).sum(axis=1)), TWO_PI)
    return float(r.mean())


def one_block(n_steps: int) -> float:
    """A diagram of one KuramotoGroup block and one OrderParameter block."""
    d = Diagram()
    group = d.add("group", KuramotoGroup(OMEGA, GAIN))
    order = d.add("order", OrderParameter())
    d.connect(group.theta, order.theta)
    d.add("r", Probe())
    d.connect(order.r, "r.u")
    return float(Simulator(d).run(n_steps=n_steps)["r"].mean())


def per_oscillator(n_steps: int) -> float:
    """A diagram of one KuramotoOscillator block per participant, a Mux and an OrderParameter."""
    n = len(OMEGA)
    d = Diagram()
    osc = [d.add(f"osc{i}", KuramotoOscillator(OMEGA[i], GAIN, 2)) for i in range(n)]
    mux = d.add("mux", Mux(n))
    for i in range(n):
        d.connect(osc[(i - 1) % n].theta, osc[i].theta_0)
        d.connect(osc[(i + 1) % n].theta, osc[i].theta_1)
        d.connect(osc[i].theta, getattr(mux, f"u{i}"))
    order = d.add("order", OrderParameter())
    d.connect(mux.y, order.theta)
    d.add("r", Probe())
    d.connect(order.r, "r.u")
    return float(Simulator(d).run(n_steps=n_steps)["r"].mean())


def python_control(n_steps: int) -> float:
    """The same network as a python-control discrete-time nlsys run by input_output_response."""
    import control

    a = ring_adjacency(len(OMEGA))

    def update(t, x, u, params):
        return np.mod(x + DT * (OMEGA + GAIN * (a * np.sin(x[None, :] - x[:, None])).sum(axis=1)), TWO_PI)

    def output(t, x, u, params):
        return np.hypot(np.cos(x).sum(), np.sin(x).sum()) / len(x)

    sys = control.nlsys(update, output, inputs=0, outputs=1, states=len(OMEGA), dt=DT)
    resp = control.input_output_response(sys, T=np.arange(n_steps) * DT, X0=np.zeros(len(OMEGA)))
    return float(np.mean(resp.outputs))


def _best_time(fn: Callable[[int], float], n_steps: int, repeats: int) -> tuple[float, float]:
    best, value = float("inf"), float("nan")
    for _ in range(repeats):
        start = time.perf_counter()
        value = fn(n_steps)
        best = min(best, time.perf_counter() - start)
    return best, value


def run(quick: bool = False) -> Iterator[dict]:
    """Time the four builds; yield one result per build."""
    n_steps = 3001 if quick else 30001
    repeats = 1 if quick else 3
    timings: dict[str, tuple[float, float]] = {}
    # interleave the builds so that machine noise hits them alike
    for _ in range(repeats):
        for name, fn in (("numpy", numpy_loop), ("one_block", one_block), ("per_oscillator", per_oscillator)):
            t, value = _best_time(fn, n_steps, 1)
            prev = timings.get(name, (float("inf"), value))
            timings[name] = (min(prev[0], t), value)
    timings["python_control"] = _best_time(python_control, n_steps, 1)
    ref_time, ref_r = timings["numpy"]
    for name, (t, r_mean) in timings.items():
        if abs(r_mean - ref_r) > 1e-9:
            raise AssertionError(f"engine.kuramoto.{name} gave r_mean {r_mean}, the NumPy loop {ref_r}")
        yield {
            "name": f"engine.kuramoto.{name}",
            "value": t,
            "unit": "s",
            "reference": ref_time,
            "ratio": t / ref_time,
            "r_mean": r_mean,
            "n_steps": n_steps,
        }
