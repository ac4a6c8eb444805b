"""Whole-run optimal control of the L2 alteration: the per-group bound of the held-out evaluation.

Within the blender's limits, the reference can only choose the alteration ``a_k = θ_L2 − θ_L0`` of each tick
in ``[−λ_k, λ_k]`` (the clip makes any θ_ref beyond the limit equivalent to ``±λ_k``), and λ_k follows from the
alterations already made. So the open-loop references θ_ref are exactly the sequences ``s_k = a_k / λ_k`` in
``[−1, 1]``, with ``θ_ref,k = θ_L0,k + λ_k s_k``: every closed-loop policy is one of them, doing nothing is
``s ≡ 0``, and the box is the whole feasible set. :func:`windowed_control_bound` maximises the run's mean r
over ``s`` on the *exact* discrete model of the simulation (the blocks' 10 ms Euler step of the group, the
blender's hard clip, ψ and κ switch, the order parameter of the phases with θ_L2 substituted; only the
phases are left unwrapped), in three stages:

1. starts, whole run, all simulated at once: doing nothing, the circular mean of the others (the ``mean``
   policy), and constant reference frequencies θ_ref0 + ω_c t (the grid of
   :func:`~cogblocks.evaluation.sync_bound.constant_frequency_scan`, plus ω_c every 0.05 rad/s from
   min ω − 1 to max ω + 1 at θ_ref0 = 0), and with ``pace`` / ``guard`` the references those closed-loop
   policies make (:mod:`cogblocks.analysis.sync_starts`); the best is the incumbent, at tick resolution;
2. block-coordinate ascent on the whole run: for consecutive windows of ``window`` s, the incumbent's ``s``
   is corrected by piecewise-linear δ on ``knot`` s knots (kept in the box by linear constraints), IPOPT
   maximising r over the window and a ``tail`` after it (where the incumbent continues) from the state the
   incumbent reaches at the window's start; the correction is kept only if the mean r of the *whole run*
   (every tick to the end, re-rolled exactly) rises. Every accepted step raises the whole-run objective.
   Each of ``passes`` sweeps the whole run once more, from the last sweep's result, with its own windows;
3. the final ``s`` is turned into θ_ref and re-simulated through the real blocks
   (:func:`resimulate`): that value is returned.

On a noisy group (``SyncGroup.noise``) the search is clairvoyant: the noise draw does not depend on what L2
does (:class:`~cogblocks.sync.group.KuramotoGroup` draws it per tick whatever the state), so its phase increments
(:meth:`~cogblocks.sync.group.KuramotoGroup.noise_path`) are a known exogenous input of the model
(:func:`known_noise_tick_model`), the closed-loop ``mean`` rule on the noisy group is a start too, and the
re-simulation runs the noisy plant with the same draw. It is the best r found for a controller that knows the
noise, the yardstick of any controller that does not.

It is a local optimum of the whole-run problem (for moves of one window at a time), started from the best
of the starts, so it is at least r without L2, ``mean``'s r and the best constant frequency's (up to the
rounding of the re-simulation); not a proof that no reference does better.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import casadi as ca
import numpy as np

from cogblocks.analysis.sync_starts import closed_loop_start, policy_starts, start_references
from cogblocks.blocks import Playback, Probe, Select, Substitute
from cogblocks.data.groups import SyncGroup
from cogblocks.sim import Diagram, Simulator
from cogblocks.sync.blender import Blender
from cogblocks.sync.group import KuramotoGroup
from cogblocks.sync.model import DT, BlenderParams
from cogblocks.sync.motion import MeanPhaseMotion
from cogblocks.sync.order import OrderParameter
from cogblocks.sync.whole_run import (
    CHUNK,
    alteration_rollout,
    identified_tick_model,
    initial_state,
    sweep,
    sweep_ticks,
    tick_model,
)

__all__ = [
    "THOROUGH",
    "alteration_model",
    "alteration_rollout",
    "known_noise_tick_model",
    "resimulate",
    "windowed_control_bound",
]


def resimulate(
    group: SyncGroup, theta_ref: np.ndarray, *, adjacency: Any = None, blender: BlenderParams | None = None
) -> float:
    """Time-averaged r of the group with L2 driven by the reference ``theta_ref`` (one sample per 10 ms tick).

    Runs the library's blocks (group, the blender with its hard saturation, the order parameter of the
    phases with θ_L2 substituted), so the value does not depend on any optimiser's model.
    """
    a, params = _checked(group, adjacency, blender)
    d = Diagram()
    kuramoto = d.add("group", KuramotoGroup.for_group(group, adjacency=a))
    reference = d.add("reference", Playback(np.mod(theta_ref, 2 * np.pi), unit="rad", wrapped=True))
    select = d.add("select_l0", Select(group.assisted))
    blend = d.add(
        "blender",
        Blender(params=params),
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


def _checked(group: SyncGroup, adjacency: Any, blender: BlenderParams | None) -> tuple[np.ndarray, BlenderParams]:
    a = group.adjacency() if adjacency is None else np.asarray(adjacency, dtype=float)
    if a.shape != (group.n, group.n):
        raise ValueError(f"adjacency must be {group.n}x{group.n}, got shape {a.shape}")
    return a, blender or BlenderParams()


def alteration_model(group: SyncGroup, adjacency: Any = None, blender: BlenderParams | None = None) -> ca.Function:
    """The exact discrete model mapped over :data:`CHUNK` ticks, for :func:`alteration_rollout`."""
    a, params = _checked(group, adjacency, blender)
    return tick_model(group, a, params).mapaccum("roll", CHUNK)


def known_noise_tick_model(group: SyncGroup, adjacency: np.ndarray, params: BlenderParams, n_steps: int) -> ca.Function:
    """One tick of the noisy group with its noise draw known: ``(x, s) -> (x_next, r)``, ``x = (θ, λ, k)``.

    Tick ``k`` adds the ``k``-th row of the group plant's :meth:`~cogblocks.sync.group.KuramotoGroup.noise_path`
    (looked up by the tick counter ``k`` carried in the state) to the noise-free step of
    :func:`~cogblocks.sync.whole_run.identified_tick_model`, as a frequency offset over the tick.
    """
    n = group.n
    plant = KuramotoGroup.for_group(group, assisted=False, adjacency=adjacency)
    offsets = plant.noise_path(n_steps + 1, DT) / DT
    lookup = ca.interpolant("noise", "linear", [np.arange(n_steps + 1, dtype=float)], offsets.ravel())
    base = identified_tick_model(n, group.assisted, adjacency, params)
    x, s = ca.MX.sym("x", n + 2), ca.MX.sym("s")
    omega = ca.DM(np.asarray(group.omega, dtype=float)) + lookup(x[n + 1])
    x_next, r = base(ca.vertcat(x[: n + 1], omega, group.gain), s)
    return ca.Function("known_noise_tick", [x, s], [ca.vertcat(x_next[: n + 1], x[n + 1] + 1.0), r])


#: ``windowed_control_bound(**THOROUGH)``: every policy start and three more sweeps (windows of 2, 10 and 4 s)
#: after the first: a tighter bound (a few tenths of a percentage point of mean gain on held-out groups) at about
#: three times the CPU (docs/validation/sync.md, Claim 3).
THOROUGH: dict[str, Any] = {
    "pace": True,
    "guard": True,
    "passes": ((2.0, 6.0, 0.25), (10.0, 10.0, 0.5), (4.0, 4.0, 0.25)),
}


def windowed_control_bound(
    group: SyncGroup,
    *,
    adjacency: Any = None,
    duration: float | None = None,
    blender: BlenderParams | None = None,
    window: float = 4.0,
    tail: float = 4.0,
    screen: float = 10.0,
    knot: float = 0.25,
    max_iter: int = 20,
    pace: bool = True,
    guard: bool = False,
    passes: Sequence[tuple[float, float, float]] = (),
    details: bool = False,
) -> Any:
    """The best whole-run mean r found over the blender's feasible alterations, re-simulated through the blocks.

    See the module docstring for the method.

    Parameters
    ----------
    group : SyncGroup
        The group (all phases start at 0, λ at λ_max); its graph unless ``adjacency`` is given.
    adjacency : array_like, optional
        Another graph, N × N.
    duration : float, optional
        Seconds to optimise and average over (ticks 0 … T/dt); the group's by default.
    blender : BlenderParams, optional
        The deliverable's by default.
    window, tail, knot, screen : float
        Seconds: the block optimised at a time, the time after it also scored, the spacing of the
        correction's knots (``knot`` divides ``window``; all multiples of 10 ms), and the longest time a
        rule switched to at a window's start is held (and screened over) before the incumbent resumes.
    max_iter : int
        IPOPT iterations per window.
    pace : bool
        Also start from the reference that the ``pace`` policy (:class:`~cogblocks.sync.PacingMotion`, identified
        model) makes in closed loop: a switching reference that the windows alone do not find on slow groups.
    guard : bool
        Also start from the closed-loop reference of the ``guard`` rule (:class:`~cogblocks.sync.GuardedPacingMotion`,
        told the run's length): a start the windows alone do not find, so that the bound is at least its r.
    passes : sequence of (window, tail, knot)
        Further sweeps over the whole run after the first, each from the result of the one before, with its own
        window, tail and knot (s; ``screen`` as above). Windows of other lengths find moves the first does not.
    details : bool
        Return a dict instead of the value: ``"r"`` (re-simulated), ``"r_model"`` (the optimiser's exact model),
        ``"starts"`` (best mean r per kind of start), ``"accepted"`` / ``"windows"``, ``"sweeps"`` (the model's
        mean r after each sweep) and ``"theta_ref"``.
    """
    a, params = _checked(group, adjacency, blender)
    duration = group.duration if duration is None else float(duration)
    n_steps = round(duration / DT) + 1
    sweeps = [(window, tail, knot), *(tuple(p) for p in passes)]
    ticks = [sweep_ticks(w, t, k, screen) for w, t, k in sweeps]
    noisy = group.noise is not None
    tick = known_noise_tick_model(group, a, params, n_steps) if noisy else tick_model(group, a, params)
    roll = tick.mapaccum("roll", CHUNK)
    s, starts, start_ref = start_references(group, a, n_steps, params)
    x_init = np.r_[initial_state(np.zeros(group.n), params.lam_max, params), [0.0] if noisy else []]
    states, r = alteration_rollout(roll, x_init, s)
    closed_loop = policy_starts(group, a, params, duration, pace, guard)
    if noisy:  # the noise-free rules' open-loop alterations are not the mean rule's on the noisy group
        closed_loop["mean_closed_loop"] = closed_loop_start(
            group, a, params, n_steps, MeanPhaseMotion(group.n, group.assisted)
        )
    for name, (s_policy, policy_ref) in closed_loop.items():
        states_policy, r_policy = alteration_rollout(roll, x_init, s_policy)
        starts[name] = float(r_policy.mean())
        if r_policy.sum() > r.sum():
            s, states, r, start_ref = s_policy, states_policy, r_policy, policy_ref
    accepted, history = 0, []
    for one_sweep in ticks:
        accepted += sweep(group, a, params, tick, (s, states, r), one_sweep, max_iter)
        history.append(float(r.mean()))
    theta_ref = states[:, group.assisted] + states[:, group.n] * s
    value = resimulate(group, theta_ref, adjacency=a, blender=params)
    if start_ref is not None:  # the start itself, in case the corrections gained less than the rounding
        start_value = resimulate(group, start_ref, adjacency=a, blender=params)
        if start_value > value:
            value, theta_ref = start_value, start_ref
    if not details:
        return value
    return {
        "r": value,
        "r_model": float(r.mean()),
        "starts": starts,
        "accepted": accepted,
        "windows": sum(-(-n_steps // t[0]) for t in ticks),
        "sweeps": history,
        "theta_ref": theta_ref,
    }
