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
from cogblocks.amplification.decision import DecisionSolve
from cogblocks.amplification.emission import EMISSIONS, emit_tick, guard_settings
from cogblocks.amplification.encoder import (
    CLIP_HIGH,
    N_POINTS,
    REST_SPEED,
    EncoderNet,
    resampling_matrix,
)
from cogblocks.amplification.encoder_casadi import _solver
from cogblocks.amplification.linearised import GRADIENTS, LinearisedSolver, one_blas_thread
from cogblocks.amplification.members import StackedNetworks
from cogblocks.amplification.neighbours import NeighbourPrediction
from cogblocks.amplification.plan import PlanResult
from cogblocks.amplification.solution import SolutionTable
from cogblocks.amplification.subspace import MovementSubspace, checked_subspace
from cogblocks.blocks.samples import plausible
from cogblocks.data.reach import ReachLibrary
from cogblocks.sim import Block
from cogblocks.sim.params import finite_number, flag, one_of, positive_int

__all__ = ["OptimalBlender", "PlanResult"]


class OptimalBlender(DecisionSolve, Block):
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

    What ships: the defaults are the validated setting ``cogblocks run amplification --variant optimised``
    runs: the linearised solver (sequential QPs on the exact networks), a decision's solve spread over 6
    ticks of at most 4 ms of CPU time each, up to 40 iterations; plans for ε̂ ≥ 0.99999 encoding fear and
    ε̂ ≤ 0.00001 removing it (``margin = removal_margin = 0.09999``) and for 5 mm of δ_pos
    (``terminal_margin = 15``); a realism penalty of 3000 (give it a ``subspace``: the shipped one keeps 12
    principal directions of the desired class, :func:`cogblocks.diagrams.amplification_setup.optimised_subspace`);
    the human predicted as the mean of its 5 nearest library movements; the last plan emitted as planned
    (``emit="tail"``) under a guard that predicts a human at rest to stay at rest. The lighter casadi setting
    the solver comparisons use is ``solver="sqpmethod", solve_ticks=1, iterations=10, emit="human"``.

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
        Planned ε̂ beyond the clipping threshold, against the prediction's error (0.09999: ε̂ ≥ 0.99999).
    removal_margin : float, optional
        The margin when removing fear (``e_des = 0``; 0.09999: ε̂ ≤ 0.00001); None: ``margin``.
    delta_pos : float
        δ_pos in mm (20).
    terminal_margin : float
        mm of δ_pos kept in reserve by the plan (15: the plan asks for 5 mm).
    end_speed : float
        Speed (mm/s) of the last planned sample along the reach direction; above the classifier's
        rest speed (1 mm/s) so that the restricted length is the planned one.
    knot_spacing : int
        Samples between knots (ΔT = 10).
    time_limit_ms : float
        CPU-time limit (4 ms), so that the plans do not depend on the machine's load. sqpmethod and IPOPT: of one
        solve (sqpmethod: a callback stops it before an iteration that, as long as the last, would end past it;
        IPOPT: ``max_cpu_time``), building and checking on top. linearised: of all the block does for a decision in
        one tick; no iteration starts that, as long as the last, would end past it (the last check's time kept in
        reserve on the committing tick), except that a decision with no iteration yet runs one.
    solve_ticks : int
        Ticks one decision's solve may span (linearised only; 6). With more, the decision at tick ``T`` plans from
        ``T + solve_ticks − 1`` on, the plan in force (or the table's blend, or the pass-through) covering the ticks
        before, the solve resuming at every tick until then, each within ``time_limit_ms``; committed at that tick.
    iterations : int
        Most iterations of one linearised solve (40).
    solver : {"sqpmethod", "ipopt", "linearised"}
        casadi's SQP with ``qrqp``, IPOPT (about 0.5 ms per iteration of overhead at this size), or
        :class:`~cogblocks.amplification.linearised.LinearisedSolver`: sequential QPs on the exact ReLU networks in
        NumPy (default; no Hessian; the first plan from no correction; a run out of time keeps its best acceptable
        iterate).
    sharpness : float
        β of the softplus that replaces ReLU inside casadi's solvers (10).
    rest_speed : float
        Speed (mm/s) at or below which the human is at rest (1, the classifier's).
    subspace : MovementSubspace, optional
        Realistic movements of class ``e_des`` (:func:`~cogblocks.amplification.subspace.movement_subspace`):
        the cost gains ``realism · r²/(100 mm/s)²``, ``r`` the altered movement's classifier input's
        distance from the subspace, so the plan stays near real movements of the class.
    realism : float
        Weight of that penalty against ``Σ‖u‖²`` (3000; only with ``subspace``).
    emit : {"human", "plan", "tail"}
        What a plan emits: ``v_h + u`` or the plan itself, its prediction plus ``u``, so that the
        emitted movement is the checked one, under a terminal guard; ``"tail"``: only a plan committed within
        ``knot_spacing`` samples of its end emits itself (default; :mod:`~cogblocks.amplification.emission`).
    guard_rest : bool
        Emitting a plan: the guard predicts a human measured at or below ``rest_speed`` to stay at rest (True).
    guard_margin : float
        mm of δ_pos the guard keeps in reserve (0: it bounds the final gap at δ_pos).
    track_past : bool
        With ``solve_ticks`` > 1 (linearised only): every tick of a spread solve puts the past emitted so far
        into its problem in place of the prediction, the iterations going on from there
        (:mod:`~cogblocks.amplification.past`).
    neighbours : int
        The prediction is η_i (1) or the mean of as many movements nearest to the human (5; :mod:`.neighbours`).
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
        margin: float = 0.09999,
        delta_pos: float = 20.0,
        terminal_margin: float = 15.0,
        end_speed: float = 5.0,
        knot_spacing: int = 10,
        time_limit_ms: float = 4.0,
        solver: str = "linearised",
        sharpness: float = 10.0,
        rest_speed: float = REST_SPEED,
        subspace: MovementSubspace | None = None,
        realism: float = 3000.0,
        solve_ticks: int = 6,
        iterations: int = 40,
        emit: str = "tail",
        track_past: bool = False,
        removal_margin: float | None = 0.09999,
        guard_rest: bool = True,
        guard_margin: float = 0.0,
        gradient: str = "blocks",
        predict_setup: bool = True,
        neighbours: int = 5,
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
        self.add_scratch("_pending", None)  # what output() decided, committed by update()
        self._job: dict[str, Any] | None = None  # a decision whose solve spans several ticks
        # CPU seconds of the last outcome check, kept in reserve on a committing tick: a measurement, not state
        self.add_scratch("_check_s", 0.0)
        self.add_scratch("tick_ms", [])  # records for inspection (see Notes), not state
        self.add_scratch("guarded_ticks", [])
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
        self.add_scratch("results", [])

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

    def member_eps(self, velocity: np.ndarray) -> np.ndarray:
        """ε̂ of every constrained network for a padded movement (T, 3), as the block's checks classify it
        (:meth:`StackedNetworks.eps`; the kinematic features with the block's step, the library's before it
        is in a diagram)."""
        return self._stack.eps(velocity, self.dt if self.dt > 0 else self.library.dt, self.rest_speed)
