"""A small ready diagram: a Kuramoto group and its order parameter."""

from __future__ import annotations

from typing import Any

import numpy as np

from cogblocks.blocks import Probe
from cogblocks.sim import Diagram, Simulator, Trace
from cogblocks.sync import KuramotoGroup, OrderParameter

__all__ = ["demo_run", "kuramoto_demo", "kuramoto_diagram", "plot_demo"]

# Table 2, group 3 (Alderisio et al. 2017, group 2).
_OMEGA = [2.7151, 2.9299, 4.0344, 2.1476, 3.9117, 3.7429, 3.2827]
_GAIN = 4.4 / 7


def kuramoto_diagram(omega: Any = _OMEGA, gain: float = _GAIN) -> Diagram:
    """A ring Kuramoto group with probes on its phases (``theta``) and order parameter (``r``)."""
    d = Diagram()
    group = d.add("group", KuramotoGroup(omega, gain))
    order = d.add("order", OrderParameter())
    d.connect(group.theta, order.theta)
    d.add("theta", Probe())
    d.add("r", Probe())
    d.connect(group.theta, "theta.u")
    d.connect(order.r, "r.u")
    return d


def _simulate(duration: float) -> tuple[Diagram, Trace]:
    d = kuramoto_diagram()
    sim = Simulator(d)
    return d, sim.run(n_steps=sim.steps(duration) + 1)  # t = 0 … duration inclusive


def kuramoto_demo(duration: float = 300.0, save_trace: str | None = None) -> dict[str, Any]:
    """Run :func:`kuramoto_diagram` for ``duration`` seconds (samples t = 0 … duration inclusive).

    Returns ``{"n", "gain", "duration", "r_mean"}``, ``r_mean`` the time-averaged order parameter.
    ``save_trace``: a ``.npz`` or ``.parquet`` file to write the trace to (see :meth:`Trace.save`).
    """
    result, trace = demo_run(duration)
    if save_trace:
        trace.save(save_trace)
    return result


def demo_run(duration: float = 300.0) -> tuple[dict[str, Any], Trace]:
    """:func:`kuramoto_demo`'s figures and the trace they come from."""
    d, trace = _simulate(duration)
    group = d["group"]
    return {"n": group.n, "gain": group.gain, "duration": duration, "r_mean": float(trace["r"].mean())}, trace


def plot_demo(path: str, duration: float = 300.0) -> None:
    """Draw each participant's unwrapped phase minus the group's mean, and the order parameter, to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    _, trace = _simulate(duration)
    r = trace["r"]
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(10, 5.5))
    phase = np.unwrap(trace["theta"], axis=0)
    # relative to the group's mean: the phases themselves all grow alike and overlap
    lines = ax1.plot(trace.t, phase - phase.mean(axis=1, keepdims=True), lw=1)
    ax1.legend(
        lines,
        [f"{i + 1}: ω = {w:.2f} rad/s" for i, w in enumerate(_OMEGA)],
        title="participant",
        fontsize="small",
        loc="upper left",
        bbox_to_anchor=(1.01, 1.0),
    )
    ax1.set_ylabel(r"$\theta_i$ − mean phase [rad]")
    ax1.set_title(f"Kuramoto group of {len(lines)} (Table 2, group 3; ring, gain 4.4/7), no L2")
    ax2.plot(trace.t, r, color="tab:blue", lw=1, label="r(t)")
    ax2.axhline(r.mean(), color="0.4", ls="--", lw=1, label=f"time average {r.mean():.3f}")
    ax2.set_ylim(0, 1.02)
    ax2.set_ylabel("order parameter r")
    ax2.set_xlabel("t [s]")
    ax2.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
