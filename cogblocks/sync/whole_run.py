"""The exact discrete model of a group with its blender, and the search over its alterations that plans a whole run.

Within the blender's limits, a reference can only choose the alteration ``a_k = θ_L2 − θ_L0`` of each tick in
``[−λ_k, λ_k]``, so a plan is a sequence of alteration fractions ``s_k = a_k / λ_k`` in ``[−1, 1]``
(``θ_ref,k = θ_L0,k + λ_k s_k``). The offline bound (:mod:`cogblocks.analysis.sync_ocp`) and the planning motion
computer (:class:`~cogblocks.sync.planned.PlannedMotion`) search with:

* :func:`tick_model`: one 10 ms tick of the group, the blender (hard clip, ψ, κ switch) and the order parameter of
  the phases with θ_L2 substituted, as a casadi function; :func:`alteration_rollout` runs it over a plan;
* :func:`rule_rollouts`: simple reference rules (doing nothing, the others' circular mean, constant frequencies) in
  closed loop on the same model in NumPy, all at once; :func:`switch_rules` the rules a window can switch to;
* :func:`sweep`: block-coordinate ascent over windows (a rule, or IPOPT on knots), kept only if the mean r rises;
* :func:`rule_plan`, :func:`refine_plan`, :func:`plan_alterations`: the best rule from a state, then sweeps.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import casadi as ca
import numpy as np

from cogblocks.data.groups import SyncGroup
from cogblocks.sync.blending import BlenderParams, alteration, lam_step
from cogblocks.sync.model import DT
from cogblocks.sync.rollouts import CHUNK, alteration_rollout, memory, rollout_function, rule_rollouts

__all__ = [
    "CHUNK",
    "alteration_rollout",
    "identified_tick_model",
    "initial_state",
    "memory",
    "played",
    "plan_alterations",
    "refine_plan",
    "rule_plan",
    "rollout_function",
    "rule_rollouts",
    "state_rules",
    "sweep",
    "sweep_solvers",
    "sweep_ticks",
    "switch_rules",
    "tick_model",
]


def _tick(
    x: ca.SX,
    s: ca.SX,
    omega: ca.SX | ca.DM,
    gain: ca.SX | float,
    n: int,
    assisted: int,
    adjacency: np.ndarray,
    params: BlenderParams,
) -> tuple[ca.SX, ca.SX, ca.SX]:
    """One tick's expressions from ``x = (θ, λ, …, a_prev)``: the next θ, the next λ, the r of this tick and the
    alteration of this tick (``a_prev`` is the state's last entry, there only with a slew limit)."""
    theta, lam = x[:n], x[n]
    shift = lam * s
    if params.slew is not None:
        # a plan asks for alterations within ±λ, where the continuous law's unwrapping changes nothing: the
        # slew limit is what the blender does to them
        shift = alteration(shift, lam, replace(params, continuous=False), x[-1], DT)
    seen = ca.vertcat(theta[:assisted], theta[assisted] + shift, theta[assisted + 1 :])
    sin_s, cos_s = ca.sin(seen), ca.cos(seen)
    r = ca.sqrt(ca.sum1(cos_s) ** 2 + ca.sum1(sin_s) ** 2) / n
    a = ca.sparsify(ca.DM(adjacency))
    pull = cos_s * ca.mtimes(a, sin_s) - sin_s * ca.mtimes(a, cos_s)
    return theta + DT * (omega + gain * pull), lam_step(lam, shift, params, DT), r, shift


def played(states: np.ndarray, s: np.ndarray, n: int, params: BlenderParams) -> np.ndarray:
    """The alterations (rad) the blender gives a plan of fractions ``s`` whose states before each tick are
    ``states``: ``λ_k s_k``, or with a slew limit what the limit leaves of them (what a motion computer then asks
    for: the blender passes it unchanged)."""
    requested = states[:, n] * s
    if not memory(params) or not len(s):
        return requested
    out = np.empty_like(requested)
    out[:-1] = states[1:, -1]
    out[-1] = alteration(requested[-1], states[-1, n], replace(params, continuous=False), states[-1, -1], DT)
    return out


def initial_state(theta: np.ndarray, lam: float, params: BlenderParams, previous: float = 0.0) -> np.ndarray:
    """``(θ, λ)``, with the last alteration ``previous`` appended when the blender has a slew limit."""
    return np.r_[theta, lam, [previous] * memory(params)]


def tick_model(group: SyncGroup, adjacency: np.ndarray, params: BlenderParams) -> ca.Function:
    """One tick of the exact discrete model: ``(x, s) -> (x_next, r)``, ``x = (θ_1 … θ_N, λ)``."""
    x, s = ca.SX.sym("x", group.n + 1 + memory(params)), ca.SX.sym("s")
    omega = ca.DM(np.asarray(group.omega, dtype=float))
    theta, lam, r, shift = _tick(x, s, omega, group.gain, group.n, group.assisted, adjacency, params)
    return ca.Function("tick", [x, s], [ca.vertcat(theta, lam, *[shift] * memory(params)), r])


def identified_tick_model(n: int, assisted: int, adjacency: np.ndarray, params: BlenderParams) -> ca.Function:
    """:func:`tick_model` with the model's parameters in the state: ``x = (θ_1 … θ_N, λ, ω_1 … ω_N, K)``, ω and K
    carried unchanged. One function (and every solver built on it) serves every model identified for a group."""
    x, s = ca.SX.sym("x", 2 * n + 2 + memory(params)), ca.SX.sym("s")
    omega, gain = x[n + 1 : 2 * n + 1], x[2 * n + 1]
    theta, lam, r, shift = _tick(x, s, omega, gain, n, assisted, adjacency, params)
    return ca.Function("identified_tick", [x, s], [ca.vertcat(theta, lam, omega, gain, *[shift] * memory(params)), r])


def switch_rules(
    group: SyncGroup,
    adjacency: np.ndarray,
    params: BlenderParams,
    state: np.ndarray,
    s_now: float,
    n_ticks: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Rules to switch to at a window's start: nothing, the mean, 16 constant frequencies from the reference
    now or from the others' mean. Their r per tick and alteration fractions over ``n_ticks``."""
    n, i = group.n, group.assisted
    omega = np.asarray(group.omega, dtype=float)
    grid = np.linspace(omega.min() - 0.5, omega.max() + 0.5, 16)
    theta = state[:n]
    reference_now = theta[i] + state[n] * s_now
    mean_now = np.angle(np.exp(1j * np.delete(theta, i)).sum())
    kind = np.r_[0, 1, np.full(2 * len(grid), 2)]
    phase0 = np.r_[0.0, 0.0, np.full(len(grid), reference_now), np.full(len(grid), mean_now)]
    return rule_rollouts(group, adjacency, params, state, (kind, phase0, np.r_[0.0, 0.0, grid, grid]), n_ticks, True)


def _window_solver(tick: ca.Function, window: int, tail: int, knot: int, max_iter: int, expand: bool = False) -> tuple:
    """IPOPT over the piecewise-linear correction δ of one window; its hat matrix (window ticks × knots).

    ``expand`` makes the NLP one SX graph: slower to build (seconds at N = 15), about 40 % faster to solve."""
    length = window + tail
    knots = window // knot
    ticks = np.arange(window)
    hats = np.maximum(0.0, 1.0 - np.abs(ticks[:, None] / knot - np.arange(knots)[None, :]))
    delta = ca.MX.sym("delta", knots)
    x0, base, weight = ca.MX.sym("x0", tick.size1_in(0)), ca.MX.sym("base", length), ca.MX.sym("weight", length)
    s = base + ca.vertcat(ca.mtimes(ca.DM(hats), delta), ca.DM.zeros(tail))
    _, r = tick.mapaccum("window", length)(x0, s.T)
    nlp = {
        "x": delta,
        "p": ca.vertcat(x0, base, weight),
        "f": -ca.dot(weight, r.T) / window,
        "g": ca.mtimes(ca.sparsify(ca.DM(hats)), delta),
    }
    options = {
        "print_time": False,
        "ipopt.print_level": 0,
        "ipopt.sb": "yes",
        "ipopt.max_iter": max_iter,
        "ipopt.hessian_approximation": "limited-memory",
        "ipopt.tol": 1e-6,
        "expand": expand,
    }
    return ca.nlpsol("window_bound", "ipopt", nlp, options), hats


def sweep_solvers(tick: ca.Function, ticks: tuple[int, int, int, int], max_iter: int, solvers: dict | None) -> tuple:
    """A :func:`sweep`'s rollout, window solver and hat matrix: built afresh, or once per shape in ``solvers``
    (the solver expanded into one SX graph: seconds to build at N = 15, about 40 % faster to solve)."""
    if solvers is None:
        return tick.mapaccum("roll", CHUNK), *_window_solver(tick, *ticks[:3], max_iter)
    key = (ticks[:3], max_iter)
    if key not in solvers:
        solvers[key] = (rollout_function(tick, solvers), *_window_solver(tick, *ticks[:3], max_iter, expand=True))
    return solvers[key]


def sweep_ticks(window: float, tail: float, knot: float, screen: float) -> tuple[int, int, int, int]:
    """A sweep's ``(window, tail, knot, screen)`` in 10 ms ticks, as :func:`sweep` takes them; ``knot`` must divide
    ``window`` (both at least one tick) and ``tail`` must be >= 0."""
    ticks = tuple(round(v / DT) for v in (window, tail, knot, screen))
    if min(ticks[0], ticks[2]) < 1 or ticks[1] < 0 or ticks[0] % ticks[2]:
        raise ValueError(f"knot ({knot} s) must divide window ({window} s); tail must be >= 0")
    return ticks


def sweep(
    group: SyncGroup,
    adjacency: np.ndarray,
    params: BlenderParams,
    tick: ca.Function,
    incumbent: tuple[np.ndarray, np.ndarray, np.ndarray],
    ticks: tuple[int, int, int, int],
    max_iter: int,
    span: int | None = None,
    solvers: dict | None = None,
) -> int:
    """One block-coordinate sweep over the whole run, improving ``incumbent = (s, states, r)`` in place.

    ``tick`` is :func:`tick_model`'s model of the group (or :func:`identified_tick_model`'s);
    ``ticks = (window, tail, knot, screen)``; ``span`` (ticks) limits the sweep to the windows that start within the
    run's first ``span`` ticks (all by default). Every step is still judged on the mean r of the whole run.
    ``solvers``, a dict kept by the caller for one ``tick``, caches the rollout and the (expanded) window solver
    between sweeps. Returns the number of accepted steps.
    """
    s, states, r = incumbent
    window_ticks, tail_ticks, knot_ticks, screen_ticks = ticks
    n_steps = len(s)
    roll, solver, hats = sweep_solvers(tick, ticks, max_iter, solvers)
    length = window_ticks + tail_ticks
    accepted = 0
    for start in range(0, n_steps if span is None else min(n_steps, span), window_ticks):
        left = n_steps - start
        # 1. switch to a rule (held over the window, or `screen` s, then the incumbent again)
        r_rules, s_rules = switch_rules(group, adjacency, params, states[start], s[start], min(screen_ticks, left))
        gains = np.cumsum(r_rules, axis=0) - np.cumsum(r[start : start + len(r_rules)])[:, None]
        trials = []
        for horizon in {min(window_ticks, left), min(screen_ticks, left)}:
            best = int(np.argmax(gains[horizon - 1]))
            if gains[horizon - 1, best] > 0:
                trial = s[start:].copy()
                trial[:horizon] = s_rules[:horizon, best]
                trials.append(trial)
        # 2. refine the incumbent's window by IPOPT
        base = np.zeros(length)
        base[: min(length, left)] = s[start : start + length]
        weight = (np.arange(start, start + length) < n_steps).astype(float)
        inner = base[:window_ticks]
        solution = solver(
            x0=np.zeros(hats.shape[1]), p=np.r_[states[start], base, weight], lbg=-1.0 - inner, ubg=1.0 - inner
        )
        delta = np.asarray(solution["x"]).ravel()
        if np.isfinite(delta).all():
            trial = s[start:].copy()
            trial[:window_ticks] = np.clip(trial[:window_ticks] + (hats @ delta)[: min(window_ticks, left)], -1, 1)
            trials.append(trial)
        for trial in trials:  # kept only if the mean r of the whole run rises
            trial_states, trial_r = alteration_rollout(roll, states[start], trial)
            if trial_r.sum() > r[start:].sum():
                s[start:], states[start:], r[start:] = trial, trial_states, trial_r
                accepted += 1
    return accepted


def state_rules(group: SyncGroup, state: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rules to start a plan from ``state`` with (:func:`rule_rollouts`' ``(kind, phase0, freq)``).

    Doing nothing, the others' circular mean, and 41 constant frequencies over [min ω − 0.5, max ω + 0.5] from six
    phases: 0, π/2, π, 3π/2, the assisted participant's phase and the others' circular mean in ``state``.
    """
    n, i = group.n, group.assisted
    omega = np.asarray(group.omega, dtype=float)
    theta = state[:n]
    phases = np.r_[np.arange(4) * np.pi / 2, theta[i], np.angle(np.exp(1j * np.delete(theta, i)).sum())]
    freq, phase0 = (v.ravel() for v in np.meshgrid(np.linspace(omega.min() - 0.5, omega.max() + 0.5, 41), phases))
    return np.r_[0, 1, np.full(len(freq), 2)], np.r_[0.0, 0.0, phase0], np.r_[0.0, 0.0, freq]


def rule_plan(
    group: SyncGroup,
    adjacency: np.ndarray,
    params: BlenderParams,
    state: np.ndarray,
    n_ticks: int,
    compare_ticks: int | None = None,
) -> np.ndarray:
    """The alteration fractions over ``n_ticks`` from ``state = (θ, λ)`` of the :func:`state_rules` rule with the
    highest mean r over the first ``compare_ticks`` of them (all by default)."""
    rules = state_rules(group, state)
    compared = n_ticks if compare_ticks is None else min(n_ticks, compare_ticks)
    sums, _ = rule_rollouts(group, adjacency, params, state, rules, compared, record=False)
    top = int(np.argmax(sums))
    _, s = rule_rollouts(group, adjacency, params, state, tuple(v[top : top + 1] for v in rules), n_ticks, record=True)
    return s[:, 0].copy()


def refine_plan(
    group: SyncGroup,
    adjacency: np.ndarray,
    params: BlenderParams,
    state: np.ndarray,
    s: np.ndarray,
    sweeps: Sequence[tuple[float, float, float]],
    *,
    span: int | None = None,
    screen: float = 10.0,
    max_iter: int = 20,
    tick: ca.Function | None = None,
    solvers: dict | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The plan ``s`` (alteration fractions from ``state = (θ, λ)``) after one :func:`sweep` per
    ``(window, tail, knot)`` of ``sweeps`` (s), each from the last one's result, over the windows that start
    within the first ``span`` ticks (all by default). Every accepted step raises the plan's mean r.

    Returns ``(s, states, r)``: the fractions, the state before each tick (``len(s)`` × (N + 1), λ last) and the
    predicted r of each tick. ``tick`` (:func:`tick_model`'s model of ``group`` by default) and ``solvers`` are
    :func:`sweep`'s: with :func:`identified_tick_model`, ``state`` carries ω and K.
    """
    s = np.array(s, dtype=float)
    tick = tick_model(group, adjacency, params) if tick is None else tick
    states, r = alteration_rollout(rollout_function(tick, solvers), state, s)
    for window, tail, knot in sweeps:
        ticks = sweep_ticks(window, tail, knot, screen)
        sweep(group, adjacency, params, tick, (s, states, r), ticks, max_iter, span, solvers)
    return s, states, r


def plan_alterations(
    group: SyncGroup,
    adjacency: np.ndarray,
    params: BlenderParams,
    state: np.ndarray,
    n_ticks: int,
    sweeps: Sequence[tuple[float, float, float]],
    *,
    screen: float = 10.0,
    max_iter: int = 20,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A plan of ``n_ticks`` alteration fractions from ``state = (θ, λ)`` on ``group``'s model, its states, its r.

    The best rule of :func:`state_rules` over the whole plan (:func:`rule_plan`), then :func:`refine_plan`'s
    sweeps over all of it: the plan is never predicted worse than doing nothing. Returns ``(s, states, r)`` as
    :func:`refine_plan` does.
    """
    if n_ticks < 1:
        raise ValueError(f"a plan needs at least one tick, got {n_ticks}")
    s = rule_plan(group, adjacency, params, state, n_ticks)
    return refine_plan(group, adjacency, params, state, s, sweeps, screen=screen, max_iter=max_iter)
