"""A motion computer that re-plans the next seconds of the trial every period, from the state it observes.

:class:`RecedingPlanMotion` does nothing (θ_ref = θ_L0) while :class:`~cogblocks.sync.identification.KuramotoRLS`
identifies the group's natural frequencies and coupling from the observed phases, and keeps identifying while it
alters (the phases the group saw rebuilt from the θ_ref it emitted and the λ it received). Once the model is
trusted it decides every ``decide_every`` seconds. A decision at tick k starts from the observed state (θ, λ),
predicts the state at tick k + P (P the decision period) through the plan in force, and plans the alteration of
every tick of ``[k + P, k + P + horizon)`` on the identified model with the whole-run search of
:mod:`cogblocks.sync.whole_run`: warm-started from the plan in force (the first decision: from the best reference
rule of :func:`~cogblocks.sync.whole_run.rule_plan`), then the window sweeps of ``sweeps`` over the windows that
start within the period, every step kept only if the predicted mean r over the horizon rises. The new plan takes
over at tick k + P; until then the plan in force plays: θ_ref = θ_L0 + a_j, a_j the alteration planned for tick j.

The tick model carries the identified ω and K in its state (:func:`~cogblocks.sync.whole_run.identified_tick_model`),
so its rollouts and expanded window solvers are built once per block and reused by every decision (on a thread,
when the diagram is compiled). A decision has a whole period to finish. With ``worker="thread"`` it runs on a
background thread (casadi and IPOPT release the GIL) and the block's own ticks only hand it the state and take its
plan: what a live run at 100 Hz needs. A decision not finished when its period ends is late: the plan in force goes
on (it covers the horizon) and the block decides again as soon as the worker is free. With ``worker="inline"`` (the
default, for simulations) the decision runs in the tick that starts it, so results do not depend on the machine's
speed; a thread whose decisions are never late gives the same plans.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import casadi as ca
import numpy as np

from cogblocks.blocks.angles import wrap_angle, wrap_pi
from cogblocks.data.groups import SyncGroup
from cogblocks.sim.params import finite_number, one_of, positive_int
from cogblocks.sync.blending import BlenderParams, alteration
from cogblocks.sync.identification import usable_phases
from cogblocks.sync.model import DT
from cogblocks.sync.motion import _IdentifyingMotion
from cogblocks.sync.periods import seconds_ticks
from cogblocks.sync.rollouts import stepped
from cogblocks.sync.sweeps import checked_sweeps
from cogblocks.sync.whole_run import (
    alteration_rollout,
    identified_tick_model,
    initial_state,
    played,
    refine_plan,
    rollout_function,
    rule_plan,
    rule_rollouts,
    sweep_solvers,
    sweep_ticks,
)

__all__ = ["MARGIN", "RECEDING_SWEEPS", "RecedingPlanMotion"]

#: Default ``margin`` (mean r over the horizon): on a group locked already, predicted gains of 1e-6 are within the
#: identified model's error and lowered r by as much on validation group 7 of ``random_groups(600, "validation", 0)``.
MARGIN = 1e-4

#: Default ``sweeps`` of a decision (window, tail, knot in s): the whole-run bound's first sweep. With it, the defaults
#: ``decide_every`` = 1 s (the shortest period a decision fits on every validation group tried, N = 15 all-to-all
#: included), ``compare`` = 10 s and ``min_ticks`` = 50 were chosen on 24 short validation groups
#: (docs/validation/sync.md, Claim 1).
RECEDING_SWEEPS: tuple[tuple[float, float, float], ...] = ((4.0, 4.0, 0.25),)


class RecedingPlanMotion(_IdentifyingMotion):
    """Identifies the group, then re-plans the next ``horizon`` seconds every ``decide_every`` seconds.

    See the module docstring.

    Parameters
    ----------
    n : int
        Number of participants.
    assisted : int
        0-based index of the assisted participant.
    end : float or None
        Length of the trial (s from the block's first tick): no plan reaches past it. ``None``: no known end (a live
        session), every plan reaches ``horizon`` ahead.
    adjacency : graph spec
        The group's graph (``"ring"``, ``"all"``, ``("random", p, seed)`` or a matrix), known to the block.
    blender : BlenderParams
        The blender the plan goes through (the deliverable's by default).
    decide_every : float or None
        The decision period (s, a multiple of the 10 ms tick): a decision takes effect one period after it starts.
        ``None``: one decision, the whole trial planned at once, played open loop (``whole_trial_plan`` builds it).
    horizon : float or None
        How far a plan reaches (s): the predicted mean r over it is what a decision maximises. ``None``: to the
        trial's end (``end`` needed).
    compare : float or None
        How far ahead (s) the first decision compares the reference rules it starts from, and a later one the
        rules it may extend the plan in force with. ``None``: over the whole plan.
    extend : {"rule", "nothing"}
        What a later decision's warm start holds past the end of the plan in force (its last period): ``"rule"``,
        the best over ``compare`` of doing nothing, following the others' circular mean and going on at the
        frequency the planned reference had over its last period, in closed loop from the state predicted there;
        ``"nothing"``, no alteration. Every plan is judged on the whole horizon, so this
        is the future a decision expects beyond what it has planned.
    sweeps : sequence of (window, tail, knot)
        The window sweeps of a decision (s, multiples of the tick; ``knot`` divides ``window``), in order.
    worker : {"inline", "thread"}
        Where a decision runs: in the tick that starts it, or on a background thread (live runs).
    margin : float
        A plan is played only if its predicted mean r over the horizon beats doing nothing from the same state by
        more than this; otherwise the decision is to do nothing.
    min_ticks : int
        Observed increments before the model is trusted.
    min_excitation : float
        Information on the gain (the least squares' Schur complement) before the model is trusted.
    max_iter : int
        IPOPT iterations per window.

    Attributes
    ----------
    decide_ms : list of float
        CPU time (ms) of every finished decision, on the thread that ran it (a record, not block state).
    plans : list of (int, ndarray, ndarray)
        Every plan put in force: its first tick, its alterations (rad) and its predicted r, tick by tick (a record,
        not block state).
    late : int
        Decisions not finished when their period ended (a record, not block state).
    timeline : list of (int, int)
        The tick each decision was started at and the tick its result was taken at (-1: not yet); inline, the same
        tick. Replaying a thread's timeline offline gives its plans whatever the machine's speed (a record).

    Notes
    -----
    Plans are made on the simulation's 10 ms tick (:data:`~cogblocks.sync.model.DT`); the block refuses to run at
    another. Bad data policy: on a tick with a phase that is not finite and within one turn of [0, 2π), or a
    non-finite λ, nothing is identified or decided (a decision due then is made at the next good tick) and θ_ref
    holds its last value. A finite λ outside the blender's [λ_min, λ_max] is clipped to it. A snapshot taken while
    a thread decides does not hold that decision: the restored block decides again.
    """

    def __init__(
        self,
        n: int,
        assisted: int,
        *,
        end: float | None,
        adjacency: Any = "ring",
        blender: BlenderParams | None = None,
        decide_every: float | None = 1.0,
        horizon: float | None = 30.0,
        compare: float | None = 10.0,
        extend: str = "rule",
        sweeps: Sequence[tuple[float, float, float]] = RECEDING_SWEEPS,
        worker: str = "inline",
        margin: float = MARGIN,
        min_ticks: int = 50,
        min_excitation: float = 1.0,
        max_iter: int = 20,
        period: float | None = None,
    ) -> None:
        super().__init__(n, assisted, period, adjacency, blender)
        self.end = None if end is None else finite_number(self, "end", end, low=0.0, low_open=True)
        self.decide_ticks = None if decide_every is None else seconds_ticks(self, "decide_every", decide_every)
        if horizon is None and self.end is None:
            raise ValueError("RecedingPlanMotion: horizon=None plans to the trial's end, which needs end")
        if decide_every is None and (horizon is not None or worker != "inline"):
            raise ValueError(
                "RecedingPlanMotion: decide_every=None plans the whole trial at once, in the tick it decides: "
                f"it needs horizon=None and worker='inline', got horizon={horizon!r}, worker={worker!r}"
            )
        self.horizon_ticks = None if horizon is None else seconds_ticks(self, "horizon", horizon)
        if self.horizon_ticks is not None and self.horizon_ticks < self.decide_ticks:
            raise ValueError(
                f"RecedingPlanMotion: horizon ({horizon} s) must be at least decide_every ({decide_every} s)"
            )
        self.compare_ticks = None if compare is None else seconds_ticks(self, "compare", compare)
        self.extend = one_of(self, "extend", extend, ("rule", "nothing"))
        self.sweeps = checked_sweeps(self, sweeps)
        self.worker = one_of(self, "worker", worker, ("inline", "thread"))
        self.margin = finite_number(self, "margin", margin, low=0.0)
        self.min_ticks = positive_int(self, "min_ticks", min_ticks)
        self.min_excitation = finite_number(self, "min_excitation", min_excitation, low=0.0)
        self.max_iter = positive_int(self, "max_iter", max_iter)
        self.others = np.arange(n) != self.assisted
        self.add_state("previous", np.full(2 * n, math.nan))  # the phases seen and observed last tick (NaN: bad)
        self.add_state("plan_s", None)  # the plan in force: alteration fractions of ticks plan_start, …
        self.add_state("plan_a", None)  # … and its alterations (rad)
        self.add_state("plan_start", -1)
        # a decision's plan until it starts: fractions, alterations, predicted r (arrays; a snapshot file holds them)
        self.add_state("pending_s", None)
        self.add_state("pending_a", None)
        self.add_state("pending_r", None)
        self.add_state("pending_start", -1)  # -1: no decision pending
        self.add_state("next_decision", -1)  # the first tick a decision may start (-1: as soon as identified)
        self.add_state("theta_ref_now", 0.0)
        self.add_state("shift", 0.0)  # the blender's alteration of the last tick, as its law gives it
        self._model: ca.Function | None = None  # identified_tick_model, and the solvers built on it
        self._solvers: dict = {}
        self._executor: ThreadPoolExecutor | None = None
        self._future: Future | None = None
        self.decide_ms: list[float] = []
        self.plans: list[tuple[int, np.ndarray, np.ndarray]] = []
        self.late = 0
        self.timeline: list[tuple[int, int]] = []

    @property
    def decision_period(self) -> float:
        """Seconds between decisions (``decide_every``); infinite for the one decision of ``decide_every=None``."""
        return math.inf if self.decide_ticks is None else self.decide_ticks * DT

    def reset(self) -> None:
        super().reset()
        self._future = None
        self.decide_ms, self.plans, self.late, self.timeline = [], [], 0, []

    def setup(self) -> None:
        super().setup()
        if self.worker == "thread":  # build the solvers now: the first decision has a period, not seconds
            tick = self._tick()
            rollout_function(tick, self._solvers)
            for window, tail, knot in self.sweeps:
                sweep_solvers(tick, sweep_ticks(window, tail, knot, 10.0), self.max_iter, self._solvers)

    def close(self) -> None:
        """Stop the worker thread (a decision still running is dropped); a later decision starts a new one."""
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)
        self._executor, self._future = None, None

    def alteration(self, k: int) -> float:
        """The alteration (rad) the plan in force gives tick ``k`` (0 outside it)."""
        j = k - self.plan_start
        return float(self.plan_a[j]) if self.plan_a is not None and 0 <= j < len(self.plan_a) else 0.0

    def output(self, k: int) -> None:
        theta = np.asarray(self.theta.value, dtype=float)
        if usable_phases(theta):
            self.theta_ref_now = wrap_angle(float(theta[self.assisted]) + self.alteration(k))
        self.theta_ref.value[...] = self.theta_ref_now

    def update(self, k: int) -> None:
        self._take_decision(k)
        theta, lam = np.asarray(self.theta.value, dtype=float), float(self.lam.value)
        if not (usable_phases(theta) and math.isfinite(lam)):
            self.previous[...] = math.nan
            return
        lam = min(max(lam, self.blender.lam_min), self.blender.lam_max)
        dt = self.dt * self.every
        rls = self.identifier()
        n = self.n
        if usable_phases(self.previous) and rls.observe(self.previous[:n], self.previous[n:], theta, dt):
            self.count += 1
        l0 = float(theta[self.assisted])
        seen = theta.copy()
        # the alteration the blender gives this tick, by its own law (the continuous one remembers the last)
        last_shift = self.shift
        self.shift = alteration(float(wrap_pi(self.theta_ref_now - l0)), lam, self.blender, last_shift, dt)
        seen[self.assisted] = wrap_angle(l0 + self.shift)
        self.previous[:n], self.previous[n:] = seen, theta
        if k < self.next_decision or self._future is not None or self.pending_start >= 0:
            return
        if self.count < self.min_ticks or rls.gain_excitation() < self.min_excitation:
            return
        omega, gain = rls.estimate()
        if not (np.isfinite(omega).all() and math.isfinite(gain)):
            return
        if abs(dt - DT) > 1e-12:
            raise RuntimeError(f"RecedingPlanMotion plans on the {DT} s tick of cogblocks.sync.model.DT, not {dt} s")
        start = k + (self.decide_ticks or 1)  # one decision (decide_every=None): its plan starts at the next tick
        self.next_decision = start
        if self.end is None:
            stop = start + self.horizon_ticks
        else:
            stop = round(self.end / DT) + 1
            stop = stop if self.horizon_ticks is None else min(stop, start + self.horizon_ticks)
            self.next_decision = stop if self.decide_ticks is None else start
        if stop <= start:
            return
        state = initial_state(theta, lam, self.blender, last_shift)
        task = (omega.copy(), float(gain), state, k, start, stop, self._committed())
        if self.worker == "inline":
            self._hold(self._decide(*task))
            self.timeline.append((k, k))
            self._take_decision(k)  # a plan that starts at the next tick is in force from it
            return
        if self._executor is None:
            self._executor = ThreadPoolExecutor(1, thread_name_prefix="cogblocks-replan")
        self._future = self._executor.submit(self._decide, *task)
        self.timeline.append((k, -1))

    def _committed(self) -> tuple[np.ndarray, np.ndarray, int] | None:
        """The plan in force (alterations, fractions, first tick), copied for a decision, or ``None``."""
        if self.plan_a is None:
            return None
        return self.plan_a.copy(), self.plan_s.copy(), self.plan_start

    def _take_decision(self, k: int) -> None:
        """Collect a thread's decision; at the tick before a decision's plan starts, make it the plan in force.

        A thread's decision still running then is late (counted once); its plan is dropped when it comes.
        """
        if self._future is not None:
            if self._future.done():
                self._hold(self._future.result())
                self.timeline[-1] = (self.timeline[-1][0], k)
                self._future = None
            elif k + 1 == self.next_decision:
                self.late += 1
        start = self.pending_start
        if 0 <= start <= k + 1:
            if k + 1 == start:
                self.plan_s, self.plan_a, self.plan_start = self.pending_s, self.pending_a, start
                self.plans.append((start, self.pending_a, self.pending_r))
            self._hold((None, None, -1, None))

    def _hold(self, decision: tuple[np.ndarray | None, np.ndarray | None, int, np.ndarray | None]) -> None:
        """Keep a decision's ``(fractions, alterations, start, predicted r)`` until its plan starts."""
        self.pending_s, self.pending_a, self.pending_start, self.pending_r = decision

    def _tick(self) -> ca.Function:
        """The group's tick model with ω and K in the state, built once: decisions reuse its solvers."""
        if self._model is None:
            self._model = identified_tick_model(self.n, self.assisted, self.adjacency, self.blender)
            self._solvers = {}
        return self._model

    def _decide(
        self,
        omega: np.ndarray,
        gain: float,
        state: np.ndarray,
        k: int,
        start: int,
        stop: int,
        committed: tuple[np.ndarray, np.ndarray, int] | None,
    ) -> tuple[np.ndarray, np.ndarray, int, np.ndarray]:
        """A decision at tick ``k`` from the observed ``state``: the plan of ticks [start, stop) as
        ``(fractions, alterations, start, predicted r)``."""
        clock = time.thread_time()
        omega_hat = tuple(float(w) for w in omega)
        model = SyncGroup("identified", self.n, gain, omega_hat, self.assisted, stop * DT, self.adjacency)
        tick = self._tick()
        state = np.asarray(state, dtype=float)
        # ω and K ride in the state of the one tick model, before the blender's memory
        x = np.r_[state[: self.n + 1], omega, gain, state[self.n + 1 :]]
        a, first = (np.zeros(0), k) if committed is None else committed[::2]  # through the plan in force …
        through = [a[j - first] if 0 <= j - first < len(a) else 0.0 for j in range(k, start)]
        x = stepped(tick, x, through, self.n)  # … to the new plan's first tick
        n_ticks = stop - start
        roll = rollout_function(tick, self._solvers)
        nothing = float(alteration_rollout(roll, x, np.zeros(n_ticks))[1].mean())
        if committed is None:
            warm = rule_plan(model, self.adjacency, self.blender, x, n_ticks, self.compare_ticks)
        else:
            warm = self._extended(model, tick, x, committed[1][start - committed[2] :][:n_ticks], n_ticks)
        s, states, r = refine_plan(
            model,
            self.adjacency,
            self.blender,
            x,
            warm,
            self.sweeps,
            span=self.decide_ticks,
            max_iter=self.max_iter,
            tick=tick,
            solvers=self._solvers,
        )
        if r.mean() <= nothing + self.margin:  # too little predicted to trust the model with: do nothing
            s = np.zeros(n_ticks)
            states, r = alteration_rollout(roll, x, s)
        self.decide_ms.append((time.thread_time() - clock) * 1e3)
        return s, played(states, s, self.n, self.blender), start, r

    def _extended(
        self, model: SyncGroup, tick: ca.Function, x: np.ndarray, old: np.ndarray, n_ticks: int
    ) -> np.ndarray:
        """The plan in force's fractions ``old`` from the new plan's first tick, continued to ``n_ticks`` as
        ``extend`` says."""
        if len(old) >= n_ticks or self.extend == "nothing":
            return np.r_[old, np.zeros(n_ticks - len(old))]
        end, n, pace = x, self.n, 0.0
        if len(old):
            states, _ = alteration_rollout(rollout_function(tick, self._solvers), x, old)
            end = np.asarray(tick(states[-1], old[-1])[0], dtype=float).ravel()
            # the reference's frequency over the plan's last period (the tick model's phases are not wrapped)
            reference = states[:, self.assisted] + states[:, n] * old
            last = reference[-min(len(reference), self.decide_ticks) :]
            pace = (last[-1] - last[0]) / (DT * (len(last) - 1)) if len(last) > 1 else 0.0
            start_phase = reference[-1] + DT * pace
        else:
            start_phase = end[self.assisted]
        # doing nothing, the others' mean, the reference going on at its frequency
        rules = (np.array([0, 1, 2]), np.array([0.0, 0.0, start_phase]), np.array([0.0, 0.0, pace]))
        rest = n_ticks - len(old)
        compared = rest if self.compare_ticks is None else self.compare_ticks
        sums, _ = rule_rollouts(model, self.adjacency, self.blender, end, rules, compared, record=False)
        best = int(np.argmax(sums))
        _, s = rule_rollouts(
            model, self.adjacency, self.blender, end, tuple(v[best : best + 1] for v in rules), rest, True
        )
        return np.r_[old, s[:, 0]]
