"""How high can the L2 architecture push the order parameter? A per-group yardstick for every motion computer.

:func:`optimal_control_bound` optimises θ_ref over the whole run offline with casadi: direct multiple
shooting on the smooth model of :mod:`cogblocks.sync.prediction` (piecewise-constant reference frequency on
knots, RK4 steps inside each knot, IPOPT), started from the best constant frequency. The blender is
smoothed for the optimiser only: the value reported is the time-averaged r of the optimised θ_ref
re-simulated through the real blocks (:class:`~cogblocks.sync.KuramotoGroup`, :class:`~cogblocks.sync.Blender`
with its clip, :class:`~cogblocks.sync.OrderParameter`; Euler at 10 ms, every sample t = 0 … T averaged).
:func:`constant_frequency_bound` is the best of a dense grid of constant reference frequencies, and
:func:`upper_bound` the larger of the two. Both are values reached by an actual reference, so a policy
above them shows the optimiser missed a better optimum (the problem is not convex): they are the best
known, not a proof.
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from cogblocks.blocks import Playback, Probe, Select, Substitute
from cogblocks.data.groups import SyncGroup
from cogblocks.sim import Diagram, Simulator
from cogblocks.sync.blender import Blender
from cogblocks.sync.group import KuramotoGroup, ring_adjacency
from cogblocks.sync.model import DT, BlenderParams, SyncModel, order_parameter
from cogblocks.sync.order import OrderParameter
from cogblocks.sync.prediction import rk4_step, seen_order, sync_ode

__all__ = ["constant_frequency_bound", "optimal_control_bound", "resimulate", "upper_bound"]


def _setup(group: SyncGroup, adjacency: Any, duration: float | None, blender: BlenderParams | None) -> tuple:
    a = ring_adjacency(group.n) if adjacency is None else np.asarray(adjacency, dtype=float)
    if a.shape != (group.n, group.n):
        raise ValueError(f"adjacency must be {group.n}x{group.n}, got shape {a.shape}")
    duration = group.duration if duration is None else float(duration)
    return a, round(duration / DT) + 1, blender or BlenderParams()


def resimulate(
    group: SyncGroup, theta_ref: np.ndarray, *, adjacency: Any = None, blender: BlenderParams | None = None
) -> float:
    """Time-averaged r of the group with L2 driven by the reference ``theta_ref`` (one sample per 10 ms tick).

    Runs the library's blocks (group, the blender with its hard saturation, the order parameter of the
    phases with θ_L2 substituted), so the value does not depend on the optimiser's smooth model.
    """
    a, _, params = _setup(group, adjacency, 0.0, blender)
    d = Diagram()
    kuramoto = d.add("group", KuramotoGroup(group.omega, group.gain, adjacency=a, assisted=group.assisted))
    reference = d.add("reference", Playback(np.mod(theta_ref, 2 * np.pi), unit="rad", wrapped=True))
    select = d.add("select_l0", Select(group.assisted))
    blend = d.add(
        "blender",
        Blender(params.lambda_min, params.lambda_max, params.e_max, params.kappa_up, params.kappa_down),
    )
    seen = d.add("seen", Substitute(group.assisted))
    order = d.add("order", OrderParameter())
    d.add("r", Probe())
    d.connect(kuramoto.theta, select.u, seen.u)
    d.connect(select.y, blend.theta_l0)
    d.connect(reference.y, blend.theta_ref)
    d.connect(blend.theta_l2, kuramoto.theta_l2, seen.v)
    d.connect(seen.y, order.theta)
    d.connect(order.r, "r.u")
    return float(Simulator(d).run(n_steps=len(theta_ref))["r"].mean())


def _constant_grid(group: SyncGroup, a: np.ndarray, n_steps: int, params: BlenderParams, grid: np.ndarray):
    """Mean r of every constant frequency in ``grid`` on the batched NumPy model (the blocks' equations)."""
    model = SyncModel(
        omega=np.tile(np.asarray(group.omega, dtype=float), (len(grid), 1)),
        gain=np.full(len(grid), group.gain),
        adjacency=a,
        assisted=group.assisted,
        blender=params,
    )
    theta = np.zeros((len(grid), group.n))
    lam = np.full(len(grid), params.lambda_max)
    total = np.zeros(len(grid))
    for k in range(n_steps):
        seen, _, lam = model.blend(theta, np.mod(grid * k * DT, 2 * np.pi), lam)
        total += order_parameter(seen)
        theta, _ = model.advance(theta, seen, np.zeros(len(grid)), grid)
    return total / n_steps


def constant_frequency_bound(
    group: SyncGroup,
    *,
    adjacency: Any = None,
    duration: float | None = None,
    blender: BlenderParams | None = None,
    frequencies: np.ndarray | None = None,
) -> float:
    """Best time-averaged r over a grid of constant reference frequencies, θ_ref(t) = ω t.

    ``frequencies`` defaults to −15 … 15 rad/s by 0.05. The grid is scanned on the batched model; the
    best frequency is re-simulated through the blocks (:func:`resimulate`) for the value returned.
    """
    a, n_steps, params = _setup(group, adjacency, duration, blender)
    grid = np.arange(-15.0, 15.0 + 1e-9, 0.05) if frequencies is None else np.asarray(frequencies, dtype=float)
    best = grid[int(np.argmax(_constant_grid(group, a, n_steps, params, grid)))]
    return resimulate(group, best * DT * np.arange(n_steps), adjacency=a, blender=params)


def optimal_control_bound(
    group: SyncGroup,
    *,
    adjacency: Any = None,
    duration: float | None = None,
    blender: BlenderParams | None = None,
    knot: float = 0.25,
    step: float = 0.05,
    sharpness: int = 8,
    max_iter: int = 100,
) -> float:
    """Time-averaged r of θ_ref optimised over the whole run by direct multiple shooting, re-simulated.

    Parameters
    ----------
    group : SyncGroup
        The group (all phases start at 0, λ at λ_max, θ_ref at 0).
    adjacency : array_like, optional
        The graph; a ring by default.
    duration : float, optional
        Seconds to optimise and average over; the group's by default.
    blender : BlenderParams, optional
        The deliverable's by default.
    knot : float
        Length (s) of a shooting interval, over which the reference's frequency is constant.
    step : float
        RK4 step (s) inside an interval; must divide ``knot``.
    sharpness : int
        Even exponent of the smooth saturation the optimiser sees.
    max_iter : int
        IPOPT iterations.
    """
    a, n_steps, params = _setup(group, adjacency, duration, blender)
    n, ticks_per_knot, steps = group.n, round(knot / DT), round(knot / step)
    n_knots = -(-(n_steps - 1) // ticks_per_knot)
    ode = sync_ode(a, group.assisted, params, sharpness)
    x, u = ca.SX.sym("x", n + 2), ca.SX.sym("u")
    omega, gain = ca.DM(np.asarray(group.omega, dtype=float)), float(group.gain)
    xs, total = x, 0
    for _ in range(steps):
        xs = rk4_step(ode, xs, u, omega, gain, step)
        total += seen_order(xs, n, group.assisted, params, sharpness)
    interval = ca.Function("interval", [x, u], [xs, total / steps]).map(n_knots)
    # the start: the best constant frequency's trajectory on the grid's model
    grid = np.arange(-15.0, 15.0 + 1e-9, 0.05)
    w0 = grid[int(np.argmax(_constant_grid(group, a, n_steps, params, grid)))]
    states0 = _constant_states(group, a, params, w0, n_knots, ticks_per_knot)
    xv, uv = ca.MX.sym("X", n + 2, n_knots + 1), ca.MX.sym("U", 1, n_knots)
    ends, r_mean = interval(xv[:, :-1], uv)
    x_init = np.r_[np.zeros(n), params.lambda_max, 0.0]
    g = ca.vertcat(ca.vec(xv[:, 0] - x_init), ca.vec(ends - xv[:, 1:]))
    nlp = {"x": ca.vertcat(ca.vec(xv), ca.vec(uv)), "f": -ca.sum2(r_mean) / n_knots, "g": g}
    solver = ca.nlpsol(
        "sync_bound",
        "ipopt",
        nlp,
        {
            "print_time": False,
            "ipopt.print_level": 0,
            "ipopt.sb": "yes",
            "ipopt.max_iter": max_iter,
            # the start is a good feasible trajectory: stay near it instead of re-centring in the box
            "ipopt.mu_init": 1e-6,
            "ipopt.warm_start_init_point": "yes",
            "ipopt.warm_start_bound_push": 1e-9,
        },
    )
    # λ stays within reach of its dynamics (the smooth saturation divides by it)
    low, high = np.full(states0.shape, -np.inf), np.full(states0.shape, np.inf)
    low[:, n], high[:, n] = 0.5 * params.lambda_min, params.lambda_max + 0.5
    lbx, ubx = np.r_[low.ravel(), np.full(n_knots, -15.0)], np.r_[high.ravel(), np.full(n_knots, 15.0)]
    sol = solver(x0=np.r_[states0.ravel(), np.full(n_knots, w0)], lbx=lbx, ubx=ubx, lbg=0.0, ubg=0.0)
    freq = np.asarray(sol["x"]).ravel()[-n_knots:]
    theta_ref = np.r_[0.0, np.cumsum(np.repeat(freq, ticks_per_knot)[: n_steps - 1] * DT)]
    return resimulate(group, theta_ref, adjacency=a, blender=params)


def _constant_states(
    group: SyncGroup, a: np.ndarray, params: BlenderParams, w: float, n_knots: int, ticks_per_knot: int
) -> np.ndarray:
    """States (θ unwrapped, λ, θ_ref) at every knot under the constant frequency ``w``, shape (n_knots + 1, N + 2)."""
    model = SyncModel(
        omega=np.asarray(group.omega, dtype=float),
        gain=group.gain,
        adjacency=a,
        assisted=group.assisted,
        blender=params,
    )
    theta, lam, ref = np.zeros(group.n), np.array(params.lambda_max), 0.0
    unwrapped = np.zeros(group.n)
    states = [np.r_[unwrapped, lam, ref]]
    for k in range(n_knots * ticks_per_knot):
        seen, _, lam = model.blend(theta, np.array(ref % (2 * np.pi)), lam)
        nxt, _ = model.advance(theta, seen, np.array(0.0), np.array(w))
        unwrapped = unwrapped + np.angle(np.exp(1j * (nxt - theta)))
        theta, ref = nxt, ref + w * DT
        if (k + 1) % ticks_per_knot == 0:
            states.append(np.r_[unwrapped, lam, ref])
    return np.array(states)


def upper_bound(
    group: SyncGroup, *, adjacency: Any = None, duration: float | None = None, blender: BlenderParams | None = None
) -> float:
    """The larger of :func:`optimal_control_bound` and :func:`constant_frequency_bound`: the yardstick of a policy."""
    kw = {"adjacency": adjacency, "duration": duration, "blender": blender}
    return max(optimal_control_bound(group, **kw), constant_frequency_bound(group, **kw))
