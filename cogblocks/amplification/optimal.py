"""Optimisation-based blending for the PoP of Amplification: Problem (13) solved online with casadi.

The table-lookup architecture (:class:`~cogblocks.amplification.VelocityBlender`) restricts the altered velocity to a
blend ``c·v_h + (1 − c)·v_r`` with ``c`` read from w̃ for the nearest library movement. :class:`OptimalBlender` drops
the restriction and solves, at every decision point, the problem the table stands for (appendix paper: Problem (13),
the distance (3a) as objective):

    min_u   Σ_t ‖u(t)‖²                                    (closest to the human, 3a)
    s.t.    ε̂(v_a) ≥ 0.9 (e_des = 1) or ≤ 0.1 (e_des = 0)   (13b, with the clipping rule)
            ‖p_a(T) − p_h(T)‖ ≤ δ_pos                       (13c)

with ``v_a = v_h + u`` and ``u`` piecewise linear on knots every ΔT samples, over a receding horizon: the human's
future is predicted by η_i (the projector's nearest library movement, expanded to its full length; or the mean of
several, :mod:`~cogblocks.amplification.neighbours`) and only the samples up to the next decision are applied.
Cubic-spline resampling is linear in the samples for a fixed length (:func:`input_map`), so the classifier input is
affine in the knots and the only nonlinearity is the network itself (:func:`encoder_to_casadi`); the problem's
parameters are built in :mod:`cogblocks.amplification.plan`, which says why these decision variables."""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from cogblocks.amplification.blending import add_blending_ports
from cogblocks.amplification.emission import EMISSIONS, emit_tick, guard_settings, planned_movement, rebased
from cogblocks.amplification.encoder import (
    CLIP_HIGH,
    N_POINTS,
    REST_SPEED,
    EncoderNet,
    movement_length,
    resampling_matrix,
)
from cogblocks.amplification.encoder_casadi import _U_SCALE, _solver, solve_decision
from cogblocks.amplification.linearised import GRADIENTS, LinearisedSolver, one_blas_thread
from cogblocks.amplification.members import StackedNetworks
from cogblocks.amplification.neighbours import NeighbourPrediction
from cogblocks.amplification.past import follow_past
from cogblocks.amplification.plan import PlanResult, library_prediction, plan_problem, sigmoid
from cogblocks.amplification.solution import SolutionTable
from cogblocks.amplification.subspace import MovementSubspace, checked_subspace
from cogblocks.blocks.samples import plausible
from cogblocks.data.reach import ReachLibrary
from cogblocks.sim import Block
from cogblocks.sim.params import finite_number, flag, one_of, positive_int

__all__ = ["OptimalBlender", "PlanResult"]


class OptimalBlender(Block):
    """Blending by optimisation: ``v_a = v_h + u + v_u``, ``u`` re-planned at every decision (Problem 13).

    A drop-in replacement for :class:`~cogblocks.amplification.VelocityBlender` (the same ports):
    ``pop_amplification(..., blending=OptimalBlender(library, encoder, table))``. Before the
    projector's first decision the human velocity passes through. At each decision (tick ``T``,
    when ``decisions`` changes) the block solves with casadi::

        min  Σ_{T ≤ t < L} ‖u(t)‖² + ρ·s
        s.t. ±logit ε̂(R_L v_a) + s ≥ logit(0.9 + margin),  s ≥ 0      (encoding, 13b)
             ‖g + dt·Σ_t u(t)‖ ≤ δ_pos − terminal_margin            (terminal, 13c)
             d·v_a(L − 1) ≥ end_speed                                (the movement ends at L)

    ``u`` is piecewise linear on knots every ``knot_spacing`` samples from ``T − 1`` (held at the
    correction applied there, so ``v_a`` stays continuous) to ``L − 1``; ``v_a`` is the emitted past
    followed by the predicted human (η_i from ``T``, zero once the human is at rest) plus ``u``;
    ``R_L`` resamples the first ``L`` samples (:func:`input_map`); ``g`` is the position gap so far
    (the block integrates ``v_a − v_h`` itself); ``d`` is the human's reach direction so far. The
    network inside the solver is smoothed (softplus of sharpness β = ``sharpness`` instead of ReLU);
    the reported ε̂ and the acceptance checks use the exact network.

    The classifier restricts a movement to its samples up to the last one faster than 1 mm/s, so the plan fixes that
    length ``L``: at least the reference's length (and η_i's, encoding fear), past ``T`` while the human still moves
    (removing fear: only at the first plan, so that the altered movement may end sooner than the human's), never
    decreasing; from ``L`` on the block outputs zero, and the last constraint keeps the last planned sample moving,
    so the classifier sees the length the plan was made for. The encoding constraint is soft with an exact penalty
    (ρ = 1000 per logit unit): when it cannot be met, the plan gets as close as it can instead of failing. Only the
    samples up to the next decision are applied before it re-plans (receding horizon), warm-started from the
    previous plan sampled at the new knots (at the first decision, from the table's blend on the prediction) and
    from the previous multipliers.

    Fallback: a solve stopped by the time limit (or the iteration limit) is used if its iterate meets the clipping
    threshold (ε̂ > 0.9, or < 0.1) and δ_pos for the predicted movement; otherwise the previous plan is kept (it is
    defined on absolute time, so keeping it is shifting it), or at the first decision the table-lookup blend ``c =
    w̃(η_i, v_r)`` is used until a solve succeeds (pass-through without a table). ``fallbacks`` counts them;
    :attr:`results` has every decision, :attr:`solve_ms` the times of those that ran the solver and :attr:`tick_ms`
    the CPU time of every tick that worked on one (building, iterating, checking; not the ticks that only wait).

    Ports
    -----
    v_h, v_r, v_u, nearest, reference, decisions : inputs
        As :class:`~cogblocks.amplification.VelocityBlender`.
    v_a : output, shape (3,), mm/s
        The altered velocity.
    c : output, scalar
        A diagnostic: the blending coefficient whose blend of ``v_h`` and ``v_r`` is closest to
        ``v_a`` at this tick, clipped to [0, 1] (1 before the first decision, when ``v_h = v_r``
        or when an input is not finite); the table's ``c`` while falling back to it.

    Parameters
    ----------
    library : ReachLibrary
        The projector's library (η_i and the reference are indices into it).
    network : EncoderNet or sequence of EncoderNet
        The classifier(s) whose ε̂ the plan constrains. With several (an ensemble), the plan must
        meet the encoding constraint for every one of them, i.e. for the ensemble's least favourable
        ε̂ (the minimum for ``e_des = 1``, the maximum for ``e_des = 0``); the reported ε̂ and the
        acceptance checks use that member too. The table's network is best among them. Networks of the
        60 profile inputs, or (``solver="linearised"`` only) ``mlp_kinematic`` networks of the profile and
        the six kinematic features of the planned movement, constrained through their exact values and
        subgradients (:mod:`cogblocks.amplification.kinematics`).
    table : SolutionTable, optional
        w̃ on ``library`` for ``e_des``: the first warm start and the first decision's fallback.
    e_des : {0, 1}
        1: encode fear (ε̂ > 0.9); 0: remove it (ε̂ < 0.1).
    margin : float
        Planned ε̂ beyond the clipping threshold, against the prediction's error (0.05: ε̂ ≥ 0.95, or ≤ 0.05).
    removal_margin : float, optional
        The margin when removing fear (``e_des = 0``); by default ``margin``.
    delta_pos : float
        δ_pos in mm (20).
    terminal_margin : float
        mm of δ_pos kept in reserve by the plan (5: the plan asks for 15 mm).
    end_speed : float
        Speed (mm/s) of the last planned sample along the reach direction; above the classifier's
        rest speed (1 mm/s) so that the restricted length is the planned one.
    knot_spacing : int
        Samples between knots (ΔT = 10).
    time_limit_ms : float
        CPU-time limit (8 ms), so that the plans do not depend on the machine's load. sqpmethod and IPOPT: of one
        solve (sqpmethod: a callback stops it before an iteration that, as long as the last, would end past it;
        IPOPT: ``max_cpu_time``), building and checking on top. linearised: of all the block does for a decision in
        one tick; no iteration starts that, as long as the last, would end past it (the last check's time kept in
        reserve on the committing tick), except that a decision with no iteration yet runs one.
    solve_ticks : int
        Ticks one decision's solve may span (linearised only; 1). With more, the decision at tick ``T`` plans from
        ``T + solve_ticks − 1`` on, the plan in force (or the table's blend, or the pass-through) covering the ticks
        before, the solve resuming at every tick until then, each within ``time_limit_ms``; committed at that tick.
    iterations : int
        Most iterations of one linearised solve (10).
    solver : {"sqpmethod", "ipopt", "linearised"}
        casadi's SQP with ``qrqp`` (default), IPOPT (about 0.5 ms per iteration of overhead at this size), or
        :class:`~cogblocks.amplification.linearised.LinearisedSolver`: sequential QPs on the exact ReLU networks in
        NumPy (no Hessian; the first plan from no correction; a run out of time keeps its best acceptable iterate).
    sharpness : float
        β of the softplus that replaces ReLU inside casadi's solvers (10).
    rest_speed : float
        Speed (mm/s) at or below which the human is at rest (1, the classifier's).
    subspace : MovementSubspace, optional
        Realistic movements of class ``e_des`` (:func:`~cogblocks.amplification.subspace.movement_subspace`):
        the cost gains ``realism · r²/(100 mm/s)²``, ``r`` the altered movement's classifier input's
        distance from the subspace, so the plan stays near real movements of the class.
    realism : float
        Weight of that penalty against ``Σ‖u‖²`` (only with ``subspace``).
    emit : {"human", "plan", "tail"}
        What a plan emits: ``v_h + u`` (default) or the plan itself, its prediction plus ``u``, so that the
        emitted movement is the checked one, under a terminal guard; ``"tail"``: only a plan committed within
        ``knot_spacing`` samples of its end emits itself (:mod:`~cogblocks.amplification.emission`).
    guard_rest : bool
        Emitting a plan: the guard predicts a human measured at or below ``rest_speed`` to stay at rest (False).
    guard_margin : float
        mm of δ_pos the guard keeps in reserve (0: it bounds the final gap at δ_pos).
    track_past : bool
        With ``solve_ticks`` > 1 (linearised only): every tick of a spread solve puts the past emitted so far
        into its problem in place of the prediction, the iterations going on from there
        (:mod:`~cogblocks.amplification.past`).
    neighbours : int
        The prediction is η_i (1) or the mean of as many movements nearest to the human (:mod:`.neighbours`).
    gradient, predict_setup : str, bool
        Linearised: how the members' gradients are taken, whether the prediction of an iteration's time counts the
        solve's preparation (``"blocks"``, True: :class:`~cogblocks.amplification.linearised.LinearisedSolver`).

    Notes
    -----
    The solve runs in the output phase of the decision's tick (it needs the projector's new decision) and is
    committed in the update phase. :attr:`results` is a record of the decisions since the last reset, not block
    state: restoring a snapshot does not rewind it, nor a solve in flight (``solve_ticks`` > 1), which :meth:`reset`
    drops.

    Bad data policy: a non-finite ``v_h`` or ``v_u`` gives a non-finite ``v_a`` on that tick, as in
    :class:`VelocityBlender` (``v_r`` only counts while the table's ``c`` < 1 is in force); for later plans a
    non-finite or implausible sample (beyond 1 km/s, :func:`~cogblocks.blocks.samples.plausible`) is recorded as
    zero, so the solver never sees it.
    """

    def __init__(
        self,
        library: ReachLibrary,
        network: EncoderNet | Sequence[EncoderNet],
        table: SolutionTable | None = None,
        *,
        e_des: int = 1,
        margin: float = 0.05,
        delta_pos: float = 20.0,
        terminal_margin: float = 5.0,
        end_speed: float = 5.0,
        knot_spacing: int = 10,
        time_limit_ms: float = 8.0,
        solver: str = "sqpmethod",
        sharpness: float = 10.0,
        rest_speed: float = REST_SPEED,
        subspace: MovementSubspace | None = None,
        realism: float = 30.0,
        solve_ticks: int = 1,
        iterations: int = 10,
        emit: str = "human",
        track_past: bool = False,
        removal_margin: float | None = None,
        guard_rest: bool = False,
        guard_margin: float = 0.0,
        gradient: str = "blocks",
        predict_setup: bool = True,
        neighbours: int = 1,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        if not isinstance(library, ReachLibrary):
            raise ValueError(f"OptimalBlender: library must be a ReachLibrary, got {type(library).__name__}")
        self._stack = StackedNetworks(network)  # every member's first layer stacked: one product per check
        networks = self._stack.networks
        self.e_des = one_of(self, "e_des", e_des, (0, 1))
        if table is not None and (not isinstance(table, SolutionTable) or table.e_des != self.e_des):
            raise ValueError(
                f"OptimalBlender: table must be a SolutionTable for e_des={self.e_des}, "
                f"got {type(table).__name__} for e_des={getattr(table, 'e_des', None)}"
            )
        self.margin = finite_number(self, "margin", margin, low=0.0, high=1.0 - CLIP_HIGH, high_open=True)
        self.removal_margin = margin if removal_margin is None else removal_margin
        finite_number(self, "removal_margin", self.removal_margin, low=0.0, high=1.0 - CLIP_HIGH, high_open=True)
        self.delta_pos = finite_number(self, "delta_pos", delta_pos, low=0.0, low_open=True)
        self.terminal_margin = finite_number(
            self, "terminal_margin", terminal_margin, low=0.0, high=self.delta_pos, high_open=True
        )
        self.end_speed = finite_number(self, "end_speed", end_speed, low=0.0)
        self.knot_spacing = positive_int(self, "knot_spacing", knot_spacing)
        self.time_limit_ms = finite_number(self, "time_limit_ms", time_limit_ms, low=0.0, low_open=True)
        self.solver = one_of(self, "solver", solver, ("sqpmethod", "ipopt", "linearised"))
        self.sharpness = finite_number(self, "sharpness", sharpness, low=0.0, low_open=True)
        self.rest_speed = finite_number(self, "rest_speed", rest_speed, low=0.0)
        self.guard_rest, self.guard_margin, *self._guard = guard_settings(self, guard_rest, guard_margin)
        self.kinematics = self._stack.kinematics
        if self.kinematics and self.solver != "linearised":
            raise ValueError(
                f"OptimalBlender: networks with kinematic inputs need solver='linearised', got solver={self.solver!r}"
            )
        self.subspace = checked_subspace("OptimalBlender", subspace, self.e_des, 3 * N_POINTS)
        self.realism = finite_number(self, "realism", realism, low=0.0)
        self.solve_ticks = positive_int(self, "solve_ticks", solve_ticks)
        if self.solve_ticks > 1 and self.solver != "linearised":
            raise ValueError(
                f"OptimalBlender: solve_ticks > 1 needs solver='linearised', got solve_ticks={self.solve_ticks} "
                f"with solver={self.solver!r}"
            )
        self.iterations = positive_int(self, "iterations", iterations)
        self.gradient = one_of(self, "gradient", gradient, GRADIENTS)
        self.predict_setup = flag(self, "predict_setup", predict_setup)
        self._neighbours = NeighbourPrediction(self, library, neighbours)
        self.neighbours = self._neighbours.k
        self.emit = one_of(self, "emit", emit, EMISSIONS)
        self.track_past = flag(self, "track_past", track_past)
        if self.track_past and self.solver != "linearised":
            raise ValueError(f"OptimalBlender: track_past needs solver='linearised', got solver={self.solver!r}")
        self._delta = self.delta_pos - self.terminal_margin
        self.library, self.networks, self.network, self.table = library, networks, networks[0], table
        self._key = self._stack.key
        self._sign = 1.0 if self.e_des == 1 else -1.0
        stack = self._stack
        self._linear = LinearisedSolver(stack.w1, stack.b1, stack.w2, stack.b2, self._sign, gradient=self.gradient,
                                        predict_setup=self.predict_setup)  # fmt: skip
        margin = self.margin if self.e_des else self.removal_margin
        self._z_target = math.log((CLIP_HIGH + margin) / (1.0 - CLIP_HIGH - margin))
        self._z_clip = math.log(CLIP_HIGH / (1.0 - CLIP_HIGH))  # also −logit(CLIP_LOW)
        self._pending: dict[str, Any] | None = None
        self._job: dict[str, Any] | None = None  # a decision whose solve spans several ticks
        self._check_s = 0.0  # CPU seconds of the last outcome check: kept in reserve on a committing tick
        self.tick_ms: list[float] = []
        self.guarded_ticks: list[int] = []
        n = library.max_len
        add_blending_ports(self)
        self.add_state("human", np.zeros((n, 3)))  # v_h received, by tick
        self.add_state("altered", np.zeros((n, 3)))  # v_a emitted, by tick
        self.add_state("plan", np.zeros((n, 3)))  # the correction u in force, by tick
        self.add_state("end", 0)  # its planned length L; 0: no plan yet
        if self.emit != "human":  # the prediction the plan in force was made on, and whether it emits itself
            self.add_state("basis", np.zeros((n, 3)))
            self.add_state("as_planned", 0)
        self.add_state("table_c", math.nan)  # the table's c while falling back to it
        self.add_state("handled", 0)  # decisions handled
        self.add_state("multipliers", np.zeros(len(networks) + 3))  # warm start: networks, terminal, speed, slack
        self.add_state("fallbacks", 0)
        self._neighbours.declare(self)
        self.results: list[PlanResult] = []

    def setup(self) -> None:
        # build every solver and resampling matrix a decision may need now, not in the middle of the loop
        spacing, n = self.knot_spacing, len(self.human)
        for m in [3 * k for k in range(1, len(range(spacing, n - 1, spacing)) + 2)] * (self.solver != "linearised"):
            _solver(self.networks, self._key, m, self.solver, self.time_limit_ms / 1e3, self.sharpness)
        for length in range(1, n + 1):
            resampling_matrix(length)

    def reset(self) -> None:
        super().reset()
        self.results, self.tick_ms, self.guarded_ticks = [], [], []
        self._pending = self._job = None

    @property
    def solve_ms(self) -> np.ndarray:
        """Time (CPU ms, see :class:`PlanResult`) of every decision that ran the solver, in order."""
        return np.array([r.solve_ms for r in self.results if r.status != "ended"])

    def output(self, k: int) -> None:
        t = k // self.every
        self._pending = None
        if (int(self.decisions.value) > self.handled and t < len(self.human)) or self._job is not None:
            started = time.thread_time()
            with one_blas_thread():  # BLAS threads would wait for busy cores (linearised.one_blas_thread)
                self._pending = self._work(t, started)
            if "solving" in self._pending:  # a tick with a problem to solve (not a decision after the movement)
                self._pending.pop("solving")
                self.tick_ms.append((time.thread_time() - started) * 1e3)
        state = {**self._in_force(), **(self._pending or {})}
        signals = (self.v_h.value, self.v_r.value, self.v_a.value, state, self.altered, self.human)
        self.c.value[...], guarded = emit_tick(t, *signals, self.dt, self.emit, *self._guard)
        self.guarded_ticks += [t] * guarded
        self.v_a.value[...] += self.v_u.value

    def update(self, k: int) -> None:
        t = k // self.every
        if self._pending is not None:
            pending, self._pending = self._pending, None
            if "result" in pending:
                self.results.append(pending.pop("result"))
            for name, value in pending.items():
                if np.ndim(value) == 0:
                    setattr(self, name, value)
                else:
                    getattr(self, name)[...] = value  # in place: restored snapshots keep the arrays
        if t < len(self.human):
            self.human[t] = self.v_h.value if plausible(self.v_h.value) else 0.0
            self.altered[t] = self.v_a.value if plausible(self.v_a.value) else 0.0
            self._neighbours.record(self, t)

    # --- one decision ---------------------------------------------------------------------------------

    def _work(self, t: int, started: float) -> dict[str, Any]:
        """This tick's work on decisions: the state to commit in the update phase (with ``result`` when one ends)."""
        new: dict[str, Any] = {}
        if int(self.decisions.value) > self.handled and t < len(self.human):
            if self._job is not None:  # a new decision before the last one's plan took effect: end that one now
                if self._job["problem"] is not None:
                    new["solving"] = True
                new.update(self._finish(t, {}))
            new["handled"] = int(self.decisions.value)
            self._job = self._begin(t, {**self._in_force(), **new})
        job = self._job
        if job is None:
            return new
        job["ticks"] += 1
        commit = t >= job["t0"] or job["problem"] is None
        if job["problem"] is not None and (commit or job["ticks"] == 1):
            new["solving"] = True  # building, checking: ticks that only wait for the plan's tick are not counted
        if self.track_past and job["run"] is not None and job["ticks"] > 1:
            follow_past(self, job, t)  # the ticks since the decision were emitted: the solve goes on with them
            new["solving"] = True
        if job["run"] is not None and not job["run"].finished:
            # on the committing tick the last check's time stays in reserve; a decision never left without
            # any iteration (as the single-tick solve, which always runs one)
            deadline = started + self.time_limit_ms / 1e3 - (self._check_s if commit else 0.0)
            done = job["run"].done
            job["run"].run(deadline, at_least_one=commit and done == 0)
            if job["run"].done > done:
                new["solving"] = True
        job["cpu"] += time.thread_time() - started
        if commit:
            new.update(self._finish(t, new))
        return new

    def _begin(self, t: int, state: dict[str, Any]) -> dict[str, Any]:
        """Start the decision at tick ``t``: its problem, planned from ``t + solve_ticks − 1`` on, and its solve."""
        nearest, reference = int(self.nearest.value), int(self.reference.value)
        lib, n = self.library, len(self.human)
        t0 = min(t + self.solve_ticks - 1, n - 1)
        at_rest = t == 0 or np.linalg.norm(self.human[t - 1]) <= self.rest_speed
        held = library_prediction(self._neighbours.basis(self, nearest), self.human, t, moving=not at_rest)
        anchor = held[t0 - 1]  # emitting a plan, the prediction at t0 − 1
        # encoding fear, the plan lasts at least as long as η_i's movement; removing it, the reference's length
        # is enough: the altered movement may end before the human's, having covered the same distance sooner
        length = max(state["end"], int(lib.length[reference]), int(lib.length[nearest]) if self.e_des else 0)
        if not at_rest and (self.e_des or state["end"] == 0):
            length = max(length, t0 + self.knot_spacing)
        length = min(length, n)
        predicted = np.where(np.arange(n)[:, None] < t, 0.0, held)
        job = {"t": t, "t0": t0, "length": length, "predicted": predicted, "run": None, "problem": None,
               "ticks": 0, "cpu": 0.0, "reference": reference, "anchor": anchor}  # fmt: skip
        if length <= t0:  # the planned movement is over: nothing left to decide
            return job
        if t0 > t:  # the ticks before t0 emit what the state in force emits, on the prediction
            altered = self._emission(t, predicted, state)
            human = np.concatenate([self.human[:t], predicted[t:]])
        else:
            altered, human = self.altered, self.human
        problem = plan_problem(
            t0, length, predicted, altered, human, self.library.velocity[reference], self.knot_spacing, self.dt,
            [self._sign, self._z_target, self.end_speed, self._delta], self.subspace, self.realism, self.kinematics,
        )  # fmt: skip
        job["problem"] = problem
        w0 = self._initial_guess(problem, predicted, reference, nearest)
        if self.solver == "linearised":
            job["run"] = self._linear.start(
                problem, w0, self._z_target, self._z_clip, self._delta, self.delta_pos, self.iterations
            )
        else:
            job["solved"] = solve_decision(self, problem, w0)  # knots (None: fall back), multipliers, status
        return job

    def _finish(self, t: int, new: dict[str, Any]) -> dict[str, Any]:
        """End the decision in flight at tick ``t``: its plan (or the fallback) and :class:`PlanResult`."""
        job, self._job = self._job, None
        checking = time.thread_time()
        out: dict[str, Any] = {}
        problem = job["problem"]
        if problem is None:
            status = "ended"
        else:
            if job["run"] is not None:
                w, status, _ = job["run"].result()
                multipliers = np.zeros(len(self.networks) + 3)
            else:
                w, multipliers, status = job["solved"]
            t0, length = job["t0"], job["length"]
            if w is None:
                out["fallbacks"] = self.fallbacks + 1
                out["multipliers"] = np.zeros(len(self.networks) + 3)
                if self.end == 0 and self.table is not None:
                    out["table_c"] = self.table.lookup(int(self.nearest.value), job["reference"])
            else:
                plan = self.plan.copy()
                plan[t0:length] = problem["phi0"][:, None] * problem["u_prev"] + problem["phi"] @ w.reshape(3, -1).T
                plan[length:] = 0.0
                out.update(plan=plan, end=length, table_c=math.nan, multipliers=multipliers)
                if self.emit != "human":  # emitted as planned: re-anchored on what was emitted, v_a continuous
                    out["as_planned"] = planned = int(self.emit == "plan" or length - t0 <= self.knot_spacing)
                    emitted = self.altered[t0 - 1] if planned and t >= t0 > 0 else None
                    out["plan"], out["basis"] = rebased(plan, self.basis, job["predicted"], t0, problem["phi0"],
                                                        problem["u_prev"], emitted, job["anchor"])  # fmt: skip
        state = {**self._in_force(), **new, **out}
        eps, distance = self._outcome(t, job["predicted"], state)
        now = time.thread_time()
        self._check_s = now - checking
        cpu = job["cpu"] + now - checking  # the ticks before, and this tick's check (its solving is counted)
        out["result"] = PlanResult(job["t"], state["end"], eps, distance, cpu * 1e3, status, job["ticks"])
        return out

    def _initial_guess(
        self, problem: dict[str, Any], predicted: np.ndarray, reference: int, nearest: int
    ) -> np.ndarray:
        """The plan in force at the new knots; at the first plan, the table's blend on the prediction."""
        knots = problem["knots"]
        if self.end > 0:
            guess = self.plan[knots]
        elif self.table is not None and self.solver != "linearised":
            c = self.table.lookup(nearest, reference)
            guess = (1.0 - c) * (self.library.velocity[reference, knots] - predicted[knots])
        else:
            guess = np.zeros((len(knots), 3))
        return guess.T.reshape(-1) / _U_SCALE

    def _in_force(self) -> dict[str, Any]:
        """The state that decides what the block emits: the plan, its length, the table's c (and the plan's basis)."""
        state = {"plan": self.plan, "end": self.end, "table_c": self.table_c}
        return state | ({"basis": self.basis, "as_planned": self.as_planned} if self.emit != "human" else {})

    def _logit(self, x: np.ndarray) -> float:
        """The logit of the least favourable network for ``e_des`` (the minimum of ``sign·z``, times ``sign``)."""
        return float(self._sign * np.min(self._sign * self._stack.logits(x)))

    def _emission(self, t: int, predicted: np.ndarray, state: dict[str, Any]) -> np.ndarray:
        """The movement emitted under ``state`` (the past, then from ``t`` on) if the human follows ``predicted``."""
        reference = self.library.velocity[int(self.reference.value)]
        return planned_movement(t, self.altered, predicted, state, reference, self.emit)

    def _outcome(self, t: int, predicted: np.ndarray, state: dict[str, Any]) -> tuple[float, float]:
        """ε̂ and terminal distance (mm) of the movement emitted under ``state`` if the human follows ``predicted``."""
        human = np.concatenate([self.human[:t], predicted[t:]])
        altered = self._emission(t, predicted, state)
        distance = float(np.linalg.norm(self.dt * (altered - human).sum(axis=0)))
        length = movement_length(altered, self.rest_speed)
        if length == 0:
            return math.nan, distance
        return sigmoid(self._logit(self._stack.inputs(altered[:length], self.dt, self.rest_speed))), distance

    def member_eps(self, velocity: np.ndarray) -> np.ndarray:
        """ε̂ of every constrained network for a padded movement (T, 3), as the block's checks classify it
        (:meth:`StackedNetworks.eps`; the kinematic features with the block's step, the library's before it
        is in a diagram)."""
        return self._stack.eps(velocity, self.dt if self.dt > 0 else self.library.dt, self.rest_speed)
