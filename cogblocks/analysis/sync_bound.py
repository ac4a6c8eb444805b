"""How high can the L2 architecture push the order parameter? A per-group yardstick for every motion computer.

:func:`optimal_control_bound` optimises θ_ref over the whole run offline with casadi: single shooting
through the smooth model of :mod:`cogblocks.sync.prediction` integrated with the blocks' own 10 ms Euler
step (piecewise-constant reference frequency on knots, IPOPT), started from the best constant frequency and
from the closed-loop references of the MPC. The blender is smoothed for the optimiser only: the value
reported is the time-averaged r of a reference re-simulated through the real blocks
(:class:`~cogblocks.sync.KuramotoGroup`, :class:`~cogblocks.sync.Blender` with its clip,
:class:`~cogblocks.sync.OrderParameter`; Euler at 10 ms, every sample t = 0 … T averaged).
:func:`constant_frequency_bound` is the best of a dense grid of constant reference frequencies, and
:func:`upper_bound` the larger of the two. Both are values reached by an actual reference: the best known,
not a proof (the problem is not convex), so a policy above them is a finding, not a contradiction.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import casadi as ca
import numpy as np

from cogblocks.blocks import Playback, Probe, Select, Substitute
from cogblocks.data.groups import SyncGroup
from cogblocks.sim import Diagram, Simulator
from cogblocks.sync.blender import Blender
from cogblocks.sync.group import KuramotoGroup
from cogblocks.sync.l2 import L2Sync
from cogblocks.sync.model import DT, BlenderParams, SyncModel, order_parameter
from cogblocks.sync.mpc import MPCMotion
from cogblocks.sync.order import OrderParameter
from cogblocks.sync.prediction import seen_order, sync_ode

__all__ = [
    "MPC_STARTS",
    "constant_frequency_bound",
    "constant_frequency_scan",
    "optimal_control_bound",
    "resimulate",
    "upper_bound",
]


def _setup(group: SyncGroup, adjacency: Any, duration: float | None, blender: BlenderParams | None) -> tuple:
    a = group.adjacency() if adjacency is None else np.asarray(adjacency, dtype=float)
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


#: The MPC set-ups whose closed-loop references start the whole-run optimisation: the default with the true
#: and the identified model, and the short-horizon one (1 s over 0.25 s knots) that does best on group 1.
MPC_STARTS: tuple[dict[str, Any], ...] = (
    {"true": True},
    {"true": False},
    {"true": False, "replan_every": 25, "knots": 3, "step": 0.125},
)


def _mpc_reference(group: SyncGroup, a: np.ndarray, n_steps: int, params: BlenderParams, setup: dict) -> np.ndarray:
    """θ_ref (unwrapped) of the MPC in closed loop (true or identified model): a start for the optimisation."""
    d = Diagram()
    kuramoto = d.add("group", KuramotoGroup(group.omega, group.gain, adjacency=a, assisted=group.assisted))
    setup = dict(setup)
    model = {"omega": group.omega, "gain": group.gain} if setup.pop("true") else {}
    motion = MPCMotion(group.n, group.assisted, adjacency=a, blender=params, **model, **setup)
    blend = Blender(params.lambda_min, params.lambda_max, params.e_max, params.kappa_up, params.kappa_down)
    l2 = d.add("l2", L2Sync(motion, group.assisted, blend))
    d.connect(kuramoto.theta, l2.theta)
    d.connect(l2.theta_l2, kuramoto.theta_l2)
    trace = Simulator(d, probes=["l2.theta_ref"]).run(n_steps=n_steps)
    return np.unwrap(trace["l2.theta_ref"])


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
    sharpness: int = 8,
    max_iter: int = 50,
) -> float:
    """Time-averaged r of θ_ref optimised over the whole run by single shooting, re-simulated through the blocks.

    The decision variables are the reference's frequencies on knots ``knot`` s long; the rollout is the
    blocks' own forward Euler at 10 ms (:func:`~cogblocks.sync.prediction.sync_ode`, one knot's ticks per
    casadi function, chained with ``mapaccum``), so the optimiser and the re-simulation differ only by the
    smoothing of the blender. IPOPT (limited-memory quasi-Newton) starts from the best constant frequency
    and from the references that :class:`~cogblocks.sync.MPCMotion` produces in closed loop in the set-ups
    of :data:`MPC_STARTS` (their frequency averaged over each knot; with the default 0.25 s knots the
    MPC's own plans lie in the search space). Each start and each optimised reference is
    re-simulated; the best value is returned. The problem is not convex and IPOPT improves its starts only
    slightly, so this is the best reference known, not a proof of optimality.

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
        Length (s) over which the reference's frequency is constant; a multiple of 10 ms.
    sharpness : int
        Even exponent of the smooth saturation the optimiser sees.
    max_iter : int
        IPOPT iterations.
    """
    a, n_steps, params = _setup(group, adjacency, duration, blender)
    n, ticks_per_knot = group.n, round(knot / DT)
    n_knots = -(-n_steps // ticks_per_knot)
    ode = sync_ode(a, group.assisted, params, sharpness)
    x, u = ca.SX.sym("x", n + 2), ca.SX.sym("u")
    omega = ca.DM(np.asarray(group.omega, dtype=float))
    xs, total = x, 0
    for _ in range(ticks_per_knot):  # r of the tick, then its Euler step: the blocks' order within a tick
        total += seen_order(xs, n, group.assisted, params, sharpness)
        xs = xs + DT * ode(xs, u, omega, float(group.gain))
    roll = ca.Function("knot", [x, u], [xs, total]).mapaccum("roll", n_knots, [0], [0])
    w = ca.MX.sym("w", n_knots)
    _, sums = roll(ca.DM(np.r_[np.zeros(n), params.lambda_max, 0.0]), w.T)
    # the last knot may run past the end: weigh its ticks beyond n_steps out
    weights = np.ones(n_knots)
    weights[-1] = (n_steps - (n_knots - 1) * ticks_per_knot) / ticks_per_knot
    nlp = {"x": w, "f": -ca.dot(ca.DM(weights), sums.T) / n_steps}
    options = {
        "print_time": False,
        "ipopt.print_level": 0,
        "ipopt.sb": "yes",
        "ipopt.max_iter": max_iter,
        "ipopt.hessian_approximation": "limited-memory",
    }
    solver = ca.nlpsol("sync_bound", "ipopt", nlp, options)
    grid = np.arange(-15.0, 15.0 + 1e-9, 0.05)
    constant = np.full(n_knots, grid[int(np.argmax(_constant_grid(group, a, n_steps, params, grid)))])
    starts = [constant]
    for setup in MPC_STARTS:
        reference = _mpc_reference(group, a, n_knots * ticks_per_knot + 1, params, setup)
        starts.append(np.clip(np.diff(reference[::ticks_per_knot]) / (ticks_per_knot * DT), -15.0, 15.0))
    best = -np.inf
    for start in starts:
        optimised = np.asarray(solver(x0=start, lbx=-15.0, ubx=15.0)["x"]).ravel()
        for freq in (start, optimised):
            theta_ref = np.r_[0.0, np.cumsum(np.repeat(freq, ticks_per_knot)[: n_steps - 1] * DT)]
            best = max(best, resimulate(group, theta_ref, adjacency=a, blender=params))
    return best


def upper_bound(
    group: SyncGroup,
    *,
    adjacency: Any = None,
    duration: float | None = None,
    blender: BlenderParams | None = None,
    max_iter: int = 50,
) -> float:
    """The best r found: the largest of :func:`optimal_control_bound` (with ``max_iter``),
    :func:`constant_frequency_bound` and, on the group's own graph, :func:`constant_frequency_scan`.

    Each is an r that some reference reaches, so the largest is the tightest; none is a proof that no
    reference does better.
    """
    kw = {"adjacency": adjacency, "duration": duration, "blender": blender}
    best = max(optimal_control_bound(group, max_iter=max_iter, **kw), constant_frequency_bound(group, **kw))
    if adjacency is None:  # the scan simulates the group's own graph
        scanned = group if duration is None else dataclasses.replace(group, duration=float(duration))
        best = max(best, constant_frequency_scan(scanned, blender))
    return best


def constant_frequency_scan(
    group: SyncGroup,
    blender_params: BlenderParams | None = None,
    *,
    n_frequencies: int = 41,
    n_phases: int = 4,
    margin: float = 0.5,
    dt: float = DT,
) -> float:
    """Best mean order parameter over constant-frequency references, all simulated at once (fast, coarse).

    The cheap bound of the held-out evaluation (:mod:`cogblocks.experiments.sync_heldout`): a coarse grid
    around the natural frequencies, simulated on the batched model without re-simulation through the
    blocks. :func:`upper_bound` is tighter and much slower.

    Parameters
    ----------
    group : SyncGroup
        Group, graph, assisted participant and duration; the mean is over ticks ``0 … T/dt``.
    blender_params : BlenderParams, optional
        The deliverable's blender by default.
    n_frequencies : int
        Frequencies ω_c, evenly spaced over ``[min ω − margin, max ω + margin]``.
    n_phases : int
        Initial reference phases θ_ref0, evenly spaced over ``[0, 2π)``.
    margin : float
        Extension of the frequency grid beyond the natural frequencies, rad/s.
    dt : float
        Euler step, s.
    """
    if n_frequencies < 1 or n_phases < 1:
        raise ValueError("constant_frequency_scan: n_frequencies and n_phases must be at least 1")
    omega = np.asarray(group.omega, dtype=float)
    frequencies = np.linspace(omega.min() - margin, omega.max() + margin, n_frequencies)
    phases = np.arange(n_phases) * (2.0 * np.pi / n_phases)
    omega_c, phase0 = (x.ravel() for x in np.meshgrid(frequencies, phases))
    model = SyncModel.from_group(group, blender=blender_params, dt=dt)
    params, a, n = model.blender, model.assisted, group.n
    # One lean Euler loop on complex phasors (a few NumPy calls per tick: this loop is the cost of the bound).
    # Same equations as SyncModel.blend/advance; the wraps are dropped where sin/cos make them moot.
    n_steps = round(group.duration / dt)
    theta = np.zeros((len(omega_c), n))
    lam = np.full(len(omega_c), params.lambda_max)
    r_sum = np.zeros(len(omega_c))
    slope = (params.lambda_max - params.lambda_min) / params.e_max
    for k in range(n_steps + 1):
        theta_l0 = theta[:, a]
        alteration = np.clip(np.mod(phase0 + omega_c * (k * dt) - theta_l0 + np.pi, 2.0 * np.pi) - np.pi, -lam, lam)
        lam_inf = np.maximum(params.lambda_min, params.lambda_max - slope * np.abs(alteration))
        lam = lam - dt * np.where(lam <= lam_inf, params.kappa_up, params.kappa_down) * (lam - lam_inf)
        theta_tilde = theta.copy()
        theta_tilde[:, a] = theta_l0 + alteration
        z = np.exp(1j * theta_tilde)
        r_sum += np.abs(z.sum(axis=1))
        theta += dt * (model.omega + model.gain * (z.conj() * (model.adjacency @ z.T).T).imag)
    return float(r_sum.max() / (n * (n_steps + 1)))
