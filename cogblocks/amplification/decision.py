"""One decision of the optimised blender: its problem, its solve (spread over ticks), its plan or fallback.

:class:`DecisionSolve` is the part of :class:`~cogblocks.amplification.OptimalBlender` that works on a
decision: begun on the tick the projector decides, iterated within the CPU budget of each tick up to the
tick it plans from, then finished with the plan (or the fallback) and its :class:`PlanResult`. The block
declares the ports, state and settings these methods read.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from cogblocks.amplification.emission import planned_movement, rebased
from cogblocks.amplification.encoder import movement_length
from cogblocks.amplification.encoder_casadi import _U_SCALE, solve_decision
from cogblocks.amplification.past import follow_past
from cogblocks.amplification.plan import PlanResult, library_prediction, plan_problem, sigmoid

__all__ = ["DecisionSolve"]


class DecisionSolve:
    """The decision methods of :class:`~cogblocks.amplification.OptimalBlender` (a mixin of that block).

    They read the block's settings, ports and state, all declared by the block's constructor.
    """

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
