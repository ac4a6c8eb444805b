"""A small ready diagram: a Kuramoto group and its order parameter."""

from __future__ import annotations

from typing import Any

import numpy as np

from cogblocks.blocks import Probe
from cogblocks.sim import Diagram, Simulator
from cogblocks.sync import KuramotoGroup, OrderParameter

__all__ = ["kuramoto_diagram", "kuramoto_demo"]

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


def kuramoto_demo(duration: float = 300.0, plot: str | None = None) -> dict[str, Any]:
    """Run :func:`kuramoto_diagram` for ``duration`` seconds (samples t = 0 … duration inclusive)."""
    d = kuramoto_diagram()
    sim = Simulator(d)
    trace = sim.run(n_steps=sim.steps(duration) + 1)  # t = 0 … duration inclusive
    if plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(8, 5))
        ax1.plot(trace.t, np.unwrap(trace["theta"], axis=0))
        ax1.set_ylabel("unwrapped phase [rad]")
        ax2.plot(trace.t, trace["r"])
        ax2.set_ylabel("order parameter r")
        ax2.set_xlabel("t [s]")
        fig.tight_layout()
        fig.savefig(plot)
        plt.close(fig)
    group = d["group"]
    return {"n": group.n, "gain": group.gain, "duration": duration, "r_mean": float(trace["r"].mean())}
