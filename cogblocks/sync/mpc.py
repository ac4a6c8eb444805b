"""A model-predictive motion computer: θ_ref planned over seconds through the blender to maximise the order parameter.

Every ``decide_every`` seconds (a *period*, 0.5 s by default) the block solves with casadi and IPOPT

    max_u   mean_t r(θ̃(t))            over the horizon, θ̃ = the phases with θ_L2 substituted
    s.t.    the group, the blender's λ dynamics and θ_ref' = u on the smooth model of
            :mod:`cogblocks.sync.prediction` (RK4 steps of ``step`` s), |u| ≤ 15 rad/s

where ``u``, the reference's frequency, is piecewise constant on knots one period long. The first knot
is not free: it is the frequency already committed for the period in which the solve runs, so a plan
started at tick k takes effect one period later and the solve has a whole period to finish. The
block uses that period: tick k only screens the candidates (below); IPOPT then runs
``iterations_per_tick`` iterations on each following tick, every chunk warm-started from the last one's
iterate and bound multipliers, until it converges or reaches ``max_iter`` (a 10 ms tick holds a chunk, not
a whole solve). A small penalty on knot-to-knot changes keeps θ_ref a plausible movement. θ_ref is
continuous: the block integrates the frequency every tick.

The landscape has many local optima (the blender clips θ_ref − θ_L0, so a plan's cost is flat wherever the
reference is far beyond the limit, and periodic in the phase it reaches). A decision therefore first
screens candidate plans on the same cost — the previous plan shifted by one knot and constant frequencies
on a grid spanning the identified frequencies — and IPOPT (limited-memory quasi-Newton, warm-started from
the best candidate, within ±``trust`` rad/s of it) refines the best one.

The model's parameters come from online identification (:class:`~cogblocks.sync.identification.KuramotoRLS`
on the observed phases, with θ_L2 reconstructed from the θ_ref the block emitted and the λ it received),
or are given (``omega`` and ``gain``: the true model, to measure what identification costs).
"""

from __future__ import annotations

import math
import time
import warnings
from typing import Any

import casadi as ca
import numpy as np

from cogblocks.blocks.angles import wrap_angle, wrap_pi
from cogblocks.sim.params import finite_array, finite_number, one_of, positive_int
from cogblocks.sync.identification import usable_phases
from cogblocks.sync.model import BlenderParams
from cogblocks.sync.motion import OMEGA_L3_LIMIT, _IdentifyingMotion
from cogblocks.sync.periods import block_step, decision_period, period_ticks
from cogblocks.sync.prediction import rk4_step, seen_order, sync_ode

__all__ = ["MPCMotion"]

#: Weight of the squared knot-to-knot frequency changes (rad/s) against the mean order parameter.
SMOOTH_WEIGHT = 1e-4

_PLANNERS: dict[tuple, tuple[ca.Function, ca.Function]] = {}


def _planner(
    adjacency: np.ndarray, assisted: int, blender: BlenderParams, p: int, shape: tuple[int, int, float], limits: tuple
) -> tuple[ca.Function, ca.Function]:
    """The NLP of one decision (cached): the IPOPT solver, and its cost ``f(w, p)`` mapped over candidate plans.

    ``shape`` is (free knots, RK4 steps per knot, step), ``limits`` (candidates, CPU seconds and iterations
    of one chunk). The solver starts from the given iterate and bound multipliers, so chunks continue a solve.
    """
    key = (adjacency.tobytes(), assisted, blender, p, shape, limits)
    if key in _PLANNERS:
        return _PLANNERS[key]
    (knots, steps_per_knot, step), (candidates, time_limit, max_iter) = shape, limits
    n = adjacency.shape[0]
    ode = sync_ode(adjacency, assisted, blender, p)
    w = ca.SX.sym("w", knots)  # free knot frequencies, rad/s
    par = ca.SX.sym("p", 2 * n + 4)  # x0 (n + 2), omega (n), gain, committed frequency
    x, omega, gain, committed = par[: n + 2], par[n + 2 : 2 * n + 2], par[2 * n + 2], par[2 * n + 3]
    total = 0
    for u in [committed, *ca.vertsplit(w)]:
        for _ in range(steps_per_knot):
            x = rk4_step(ode, x, u, omega, gain, step)
            total += seen_order(x, n, assisted, blender, p)
    cost = -total / ((knots + 1) * steps_per_knot) + SMOOTH_WEIGHT * ca.sumsqr(ca.diff(ca.vertcat(committed, w)))
    options = {
        "print_time": False,
        "ipopt.print_level": 0,
        "ipopt.sb": "yes",
        # exact Hessians of this rollout cost more than the iterations they save at this size
        "ipopt.hessian_approximation": "limited-memory",
        "ipopt.max_iter": max_iter,
        "ipopt.max_cpu_time": time_limit,
        "ipopt.tol": 1e-5,
        # a chunk continues the previous one: start at its iterate and multipliers, with a small barrier
        "ipopt.warm_start_init_point": "yes",
        "ipopt.mu_init": 1e-4,
        "ipopt.warm_start_bound_push": 1e-9,
        "ipopt.warm_start_mult_bound_push": 1e-9,
        # a long backtracking line search made ~5-10 % of the chunks overrun the 10 ms tick; accepting the trial
        # point after 4 steps removed every overrun on Table 2's groups (30 s) without lowering their r
        "ipopt.accept_after_max_steps": 4,
    }
    solver = ca.nlpsol("mpc_sync", "ipopt", {"x": w, "p": par, "f": cost}, options)
    screen = ca.Function("mpc_cost", [w, par], [cost]).map(candidates)
    _PLANNERS[key] = (solver, screen)
    return solver, screen


class MPCMotion(_IdentifyingMotion):
    """Model-predictive motion computer: re-plans θ_ref's frequency every period to maximise the predicted r.

    See the module docstring for the problem. Decisions are taken in the update phase of ticks
    ``0, P, 2·P, …`` (P the period in ticks); a plan made at tick k commits the frequency of its first
    free knot for the period from tick k + P (receding horizon: later knots are only the
    warm start of the next decision, shifted by one knot).

    Fallback: the decision's tick makes the best candidate the plan — the previous plan shifted, unless a
    constant frequency predicts better — and each chunk of the solve that follows replaces the plan's free
    knots only if its predicted cost beats the plan's. The plan in force when the period ends is what
    applies, however far the solve got; a solve still running then is dropped for the next decision and
    counted in ``fallbacks``, as is a solve that returns a non-finite iterate.
    Before the first plan (and while the identified model is not yet usable: fewer than ``min_ticks``
    observed increments), θ_ref follows the circular mean of the others' phases, which the first plan then
    continues from. :attr:`solve_ms` holds the CPU time of every decision (its ticks summed), :attr:`tick_ms`
    that of every tick that worked on one.

    Parameters
    ----------
    n : int
        Number of participants.
    assisted : int
        0-based index of the assisted participant.
    adjacency : graph spec
        The group's graph (``"ring"``, ``"all"``, ``("random", p, seed)`` or a weighted, possibly directed
        matrix), known to the block.
    omega, gain : array_like and float, optional
        The true model; both or neither. Without them the block identifies the group online.
    blender : BlenderParams
        The blender the plan goes through (the deliverable's by default); its hard saturation also
        reconstructs θ_L2 for identification.
    decide_every : float
        Seconds per period (the knot length and the time a solve may take), a whole number of the block's steps.
    replan_every : int, optional
        Deprecated: the period in ticks; give ``decide_every`` in seconds.
    knots : int
        Free knots in the horizon (horizon = (knots + 1) periods, the committed one included: 3 s by
        default). The horizon is a trade-off measured on Table 2's groups (docs/validation/sync.md): 1 s is best
        on group 1 and 3 s on group 3, whose slow entrainment a short horizon does not see.
    step : float
        RK4 step (s) inside the NLP; must divide the period.
    sharpness : int
        Even exponent p of the smooth saturation inside the NLP (the larger, the closer to the clip).
    candidates : int
        Plans screened before the solve: the previous plan shifted, and ``candidates − 1`` constant
        frequencies from min(ω̂) − 1 to max(ω̂) + 1 rad/s.
    trust : float
        Half-width (rad/s) of the box around the best candidate that IPOPT searches.
    time_limit_ms : float
        CPU-time limit of IPOPT in one tick (``max_cpu_time`` of a chunk, checked once per iteration).
    max_iter : int
        Iteration limit of IPOPT in one decision, all chunks together. A chunk restarts the quasi-Newton
        memory, so the default is twice the 10 of one uninterrupted solve: on the decisions of Table 2's
        groups 1 and 3 (30 s), 20 chunked iterations improve on the best candidate as much as or more than
        10 uninterrupted ones (mean cost decrease 3.7e-3 against 3.3e-3 on group 1, 1.39e-4 against 1.41e-4
        on group 3).
    iterations_per_tick : int
        IPOPT iterations per tick (a chunk); ``max_iter`` or more solves in the tick after the decision.
    forgetting : float
        Forgetting factor of the identification's least squares.
    min_ticks : int
        Observed increments before the identified model is planned with.

    Notes
    -----
    :attr:`solve_ms` and :attr:`tick_ms` are records since the last reset, not block state. The decision in
    progress is block state (the plan, the solve's iterate, bound multipliers, box and parameters: IPOPT keeps
    nothing between chunks), so a diagram restored from a snapshot (``state_dict`` or ``save_state``) continues bit
    for bit, as far as the run itself is reproducible: a chunk that ``time_limit_ms`` stops ends where the
    machine's speed lets it, in a continued run as in any other.

    Bad data policy: on a tick with a phase that is not finite and within one turn of [0, 2π), or a
    non-finite λ, nothing is identified or decided and θ_ref keeps integrating the committed frequency
    (a decision due on that tick is taken at the next good tick; a solve in progress goes on, as it works on
    the state it started from); a finite λ outside the blender's [λ_min, λ_max] is clipped to it.
    """

    _theta_feedthrough = False

    def __init__(
        self,
        n: int,
        assisted: int,
        *,
        adjacency: Any = "ring",
        omega: Any = None,
        gain: float | None = None,
        blender: BlenderParams | None = None,
        decide_every: float = 0.5,
        replan_every: int | None = None,
        knots: int = 5,
        step: float = 0.25,
        sharpness: int = 8,
        candidates: int = 16,
        trust: float = 2.0,
        time_limit_ms: float = 8.0,
        max_iter: int = 20,
        iterations_per_tick: int = 2,
        forgetting: float = 1.0,
        min_ticks: int = 5,
        period: float | None = None,
    ) -> None:
        forgetting = finite_number(self, "forgetting", forgetting, low=0.0, high=1.0, low_open=True)
        super().__init__(n, assisted, period, adjacency, blender, forgetting)
        if (omega is None) != (gain is None):
            raise ValueError("MPCMotion: omega and gain must be given together (the true model) or not at all")
        self.true_model = None
        if omega is not None:
            omega = finite_array(self, "omega", omega, shape=(n,))
            self.true_model = (omega, finite_number(self, "gain", gain, low=0.0))
        self.decide_every, self._given_ticks = decision_period(
            self, decide_every, old_name="replan_every", old_value=replan_every
        )
        self.decide_ticks = period_ticks(self, self.decide_every, self._given_ticks)  # counted again when compiled
        self.knots = positive_int(self, "knots", knots)
        self.step = finite_number(self, "step", step, low=0.0, low_open=True)
        self.sharpness = one_of(self, "sharpness", sharpness, (2, 4, 6, 8, 10, 12, 16))
        self.candidates = positive_int(self, "candidates", candidates, minimum=2)
        self.trust = finite_number(self, "trust", trust, low=0.0, low_open=True)
        self.time_limit_ms = finite_number(self, "time_limit_ms", time_limit_ms, low=0.0, low_open=True)
        self.max_iter = positive_int(self, "max_iter", max_iter)
        self.iterations_per_tick = positive_int(self, "iterations_per_tick", iterations_per_tick)
        self.min_ticks = positive_int(self, "min_ticks", min_ticks, minimum=0)
        self.others = np.array([j for j in range(n) if j != self.assisted])
        self.add_state("theta_ref_now", 0.0)
        self.add_state("plan", np.full(knots + 1, math.nan))  # committed knot then the free ones; NaN: no plan
        self.add_state("plan_tick", 0)  # tick at which the plan's committed knot starts
        self.add_state("due", True)  # a decision is due at the next good tick
        self.add_state("previous", np.full(n + n, math.nan))  # θ̃ and own phases of the last good tick
        self.add_state("fallbacks", 0)
        # the solve in progress: iterate, bound multipliers, parameters, box, iterations done, the plan's cost
        self.add_state("solving", False)
        self.add_state("solve_x", np.zeros(knots))
        self.add_state("solve_lam", np.zeros(knots))
        self.add_state("solve_par", np.zeros(2 * n + 4))
        self.add_state("solve_box", np.zeros((2, knots)))
        self.add_state("solve_iterations", 0)
        self.add_state("solve_cost", math.inf)
        self.solve_ms: list[float] = []
        self.tick_ms: list[float] = []

    @property
    def decision_period(self) -> float:
        """Seconds between plans: ``decide_ticks`` ticks of the block's step."""
        return self.decide_ticks * block_step(self)

    @property
    def replan_every(self) -> int:
        """Deprecated: the period in ticks (``decide_ticks``)."""
        warnings.warn("MPCMotion.replan_every is deprecated: use decide_ticks", DeprecationWarning, stacklevel=2)
        return self.decide_ticks

    def setup(self) -> None:
        try:
            self.decide_ticks = period_ticks(self, self.decide_every, self._given_ticks)
        except ValueError as exc:
            raise self._fail(str(exc).removeprefix("MPCMotion: ")) from None
        period = self.decide_ticks * self.dt * self.every
        steps = round(period / self.step)
        if steps < 1 or not math.isclose(steps * self.step, period, rel_tol=1e-9):
            raise self._fail(f"step ({self.step} s) must divide the period ({period:g} s = decide_every)")
        self._steps_per_knot = steps
        self._planner = _planner(
            self.adjacency,
            self.assisted,
            self.blender,
            self.sharpness,
            (self.knots, steps, self.step),
            (self.candidates, self.time_limit_ms / 1e3, self.iterations_per_tick),
        )

    def reset(self) -> None:
        super().reset()
        self.solve_ms = []
        self.tick_ms = []

    def output(self, k: int) -> None:
        self.theta_ref.value[...] = self.theta_ref_now

    def frequency(self, k: int) -> float:
        """The reference's frequency (rad/s) at tick ``k`` under the plan in force (NaN before the first plan)."""
        index = min((k - self.plan_tick) // self.decide_ticks, self.knots)
        return float(self.plan[index])

    def model(self) -> tuple[np.ndarray, float] | None:
        """The ``(ω, K)`` planned with: the true model, the identified one, or ``None`` while too little is known."""
        if self.true_model is not None:
            return self.true_model
        if self.count < self.min_ticks:
            return None
        return self.identifier().estimate()

    def update(self, k: int) -> None:
        theta, lam = np.asarray(self.theta.value, dtype=float), float(self.lam.value)
        good = usable_phases(theta) and math.isfinite(lam)
        # the real blender's λ never leaves its range; a value outside is a glitch the model must not divide by
        lam = min(max(lam, self.blender.lam_min), self.blender.lam_max) if good else lam
        if good:
            self._identify(theta, lam)
        if k % self.decide_ticks == 0:
            self.due = True
        model = self.model() if good and self.due else None
        start, working = time.thread_time(), self.solving
        if model is not None:
            self._finish()  # a solve still running is out of time: the plan in force is its result
            self._decide(k, theta, lam, model)
            self.due = False
        elif working:
            self._advance()
        if model is not None or working:
            ms = (time.thread_time() - start) * 1e3
            self.tick_ms.append(ms)
            if model is not None or not self.solve_ms:  # a new decision, or one restored mid-solve from a snapshot
                self.solve_ms.append(ms)
            else:
                self.solve_ms[-1] += ms
        omega = self.frequency(k) if np.isfinite(self.plan).all() else math.nan
        if math.isfinite(omega):
            self.theta_ref_now = wrap_angle(self.theta_ref_now + self.dt * self.every * omega)
        elif good:  # no plan yet: the circular mean of the others
            others = theta[self.others]
            self.theta_ref_now = wrap_angle(math.atan2(np.sin(others).sum(), np.cos(others).sum()))

    def _identify(self, theta: np.ndarray, lam: float) -> None:
        """Add this tick's increment to the least squares; remember θ̃ (θ_L2 rebuilt from θ_ref and λ)."""
        if self.true_model is not None:
            return
        n = self.n
        if usable_phases(self.previous) and self.identifier().observe(
            self.previous[:n], self.previous[n:], theta, self.dt * self.every
        ):
            self.count += 1
        seen = theta.copy()
        l0 = theta[self.assisted]
        seen[self.assisted] = wrap_angle(l0 + min(max(float(wrap_pi(self.theta_ref_now - l0)), -lam), lam))
        self.previous[:n], self.previous[n:] = seen, theta

    def _decide(self, k: int, theta: np.ndarray, lam: float, model: tuple[np.ndarray, float]) -> None:
        """Decide at tick ``k``: screen the candidates, make the best one the plan, and start refining it."""
        _, screen = self._planner
        omega, gain = model
        has_plan = bool(np.isfinite(self.plan).all())
        low, high = float(np.min(omega)) - 1.0, float(np.max(omega)) + 1.0
        if has_plan:
            committed = self.frequency(k)
            shift = (k - self.plan_tick) // self.decide_ticks + 1  # the previous plan from the next knot, last held
            shifted = self.plan[np.minimum(np.arange(shift, shift + self.knots), self.knots)]
        else:
            committed = float(np.clip(np.mean(omega), -OMEGA_L3_LIMIT, OMEGA_L3_LIMIT))
            shifted = np.full(self.knots, committed)
        grid = np.clip(np.linspace(low, high, self.candidates - 1), -OMEGA_L3_LIMIT, OMEGA_L3_LIMIT)
        plans = np.column_stack([shifted, np.tile(grid, (self.knots, 1))])
        x0 = np.r_[theta, lam, theta[self.assisted] + wrap_pi(self.theta_ref_now - theta[self.assisted])]
        self.solve_par[...] = np.r_[x0, omega, gain, committed]
        costs = np.asarray(screen(plans, self.solve_par)).ravel()
        best = int(np.nanargmin(costs)) if np.isfinite(costs).any() else 0
        warm = plans[:, best]
        self.plan[...] = np.r_[committed, warm]
        self.plan_tick = k
        self.solve_box[...] = (
            np.maximum(warm - self.trust, -OMEGA_L3_LIMIT),
            np.minimum(warm + self.trust, OMEGA_L3_LIMIT),
        )
        self.solve_x[...], self.solve_lam[...] = warm, 0.0
        self.solve_iterations, self.solve_cost = 0, float(costs[best])
        self.solving = True

    def _advance(self) -> None:
        """Run one chunk of the solve; keep its iterate as the plan if it predicts better than the plan."""
        solver, _ = self._planner
        sol = solver(
            x0=self.solve_x, lam_x0=self.solve_lam, p=self.solve_par, lbx=self.solve_box[0], ubx=self.solve_box[1]
        )
        stats = solver.stats()
        x, cost = np.asarray(sol["x"]).ravel(), float(sol["f"])
        finite = bool(np.isfinite(x).all() and math.isfinite(cost))
        if finite and cost < self.solve_cost:
            self.plan[1:], self.solve_cost = x, cost
        if finite:
            self.solve_x[...], self.solve_lam[...] = x, np.asarray(sol["lam_x"]).ravel()
        self.solve_iterations += max(int(stats["iter_count"]), 1)
        if not finite:
            self._finish()
        elif stats["success"] or self.solve_iterations >= self.max_iter:
            self.solving = False

    def _finish(self) -> None:
        """End a solve that failed or ran out of its period, if one is in progress: a fallback."""
        if self.solving:
            self.fallbacks += 1
        self.solving = False
