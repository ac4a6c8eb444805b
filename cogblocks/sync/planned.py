"""A motion computer that identifies the group, then plans the rest of the trial at once and plays the plan.

:class:`PlannedMotion` does nothing (θ_ref = θ_L0) while :class:`~cogblocks.sync.identification.KuramotoRLS`
identifies the group's natural frequencies and coupling from the observed phases. Once the model is trusted, it
plans the alteration of every remaining tick of the trial on that model with the search of the whole-run bound
(:func:`~cogblocks.sync.whole_run.plan_alterations`: the best reference rule from the predicted state, then window
sweeps, every step kept only if the predicted mean r to the trial's end rises), and plays it: θ_ref = θ_L0 + a_k,
a_k the planned alteration of tick k. Past the plan it does nothing again.

The plan is computed in one tick: about 0.3 s of CPU per second of trial (docs/pop-sync.md, "Planning the whole
trial"), so the block is for simulated trials, not for live runs at 100 Hz. It plays the plan open loop: it is only
as good as the identified model (ω to about 5e-5 rad/s after 1 s on a simulated group; an error of 0.01 rad/s
loses most of the plan's gain over ``guard``'s, docs/pop-sync.md).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from cogblocks.blocks.angles import wrap_angle
from cogblocks.data.groups import SyncGroup
from cogblocks.sim.params import finite_number, positive_int
from cogblocks.sync.blending import BlenderParams
from cogblocks.sync.identification import usable_phases
from cogblocks.sync.model import DT
from cogblocks.sync.motion import _IdentifyingMotion
from cogblocks.sync.whole_run import initial_state, plan_alterations, played, tick_model

__all__ = ["SWEEPS", "PlannedMotion", "checked_sweeps"]

#: Default ``sweeps`` (window, tail, knot in s): the bound's first sweep, then the thorough bound's three passes.
#: Looked at on validation groups 0-59 of ``random_groups(600, "validation", 0)`` (docs/pop-sync.md).
SWEEPS: tuple[tuple[float, float, float], ...] = (
    (4.0, 4.0, 0.25),
    (2.0, 6.0, 0.25),
    (10.0, 10.0, 0.5),
    (4.0, 4.0, 0.25),
)


class PlannedMotion(_IdentifyingMotion):
    """Identifies the group while doing nothing, then plans every remaining tick of the trial and plays the plan.

    See the module docstring.

    Parameters
    ----------
    n : int
        Number of participants.
    assisted : int
        0-based index of the assisted participant.
    end : float
        Length of the trial (s from the block's first tick): the plan maximises the predicted mean r up to it.
    adjacency : graph spec
        The group's graph (``"ring"``, ``"all"``, ``("random", p, seed)`` or a matrix), known to the block.
    blender : BlenderParams
        The blender the plan goes through (the deliverable's by default).
    sweeps : sequence of (window, tail, knot)
        The plan's window sweeps (s, multiples of the 10 ms tick; ``knot`` divides ``window``), in order.
    min_ticks : int
        Observed increments before the model is trusted.
    min_excitation : float
        Information on the gain (the least squares' Schur complement) before the model is trusted.
    max_iter : int
        IPOPT iterations per window.

    Attributes
    ----------
    plan_ms : float or None
        CPU time (ms) the plan took (a record, not block state).
    predicted : ndarray or None
        The plan's predicted r of every planned tick, on the identified model (a record, not block state).

    Notes
    -----
    The plan is made on the simulation's 10 ms tick (:data:`~cogblocks.sync.model.DT`); the block refuses to run at
    another. Bad data policy: on a tick with a phase that is not finite and within one turn of [0, 2π), or a
    non-finite λ, nothing is identified or planned (a plan due then is made at the next good tick) and θ_ref holds
    its last value. A finite λ outside the blender's [λ_min, λ_max] is clipped to it.
    """

    def __init__(
        self,
        n: int,
        assisted: int,
        *,
        end: float,
        adjacency: Any = "ring",
        blender: BlenderParams | None = None,
        sweeps: Sequence[tuple[float, float, float]] = SWEEPS,
        min_ticks: int = 100,
        min_excitation: float = 1.0,
        max_iter: int = 20,
        period: float | None = None,
    ) -> None:
        super().__init__(n, assisted, period, adjacency, blender)
        self.end = finite_number(self, "end", end, low=0.0, low_open=True)
        self.sweeps = checked_sweeps(self, sweeps)
        self.min_ticks = positive_int(self, "min_ticks", min_ticks)
        self.min_excitation = finite_number(self, "min_excitation", min_excitation, low=0.0)
        self.max_iter = positive_int(self, "max_iter", max_iter)
        self.add_state("previous", np.full(n, math.nan))  # the last tick's phases (NaN: bad)
        self.add_state("plan", None)  # the planned alteration (rad) of ticks plan_start, plan_start + 1, …
        self.add_state("plan_start", -1)
        self.add_state("theta_ref_now", 0.0)
        self.plan_ms: float | None = None
        self.predicted: np.ndarray | None = None

    def reset(self) -> None:
        super().reset()
        self.plan_ms, self.predicted = None, None

    def output(self, k: int) -> None:
        theta = np.asarray(self.theta.value, dtype=float)
        if usable_phases(theta):
            j = k - self.plan_start
            planned = self.plan is not None and 0 <= j < len(self.plan)
            self.theta_ref_now = wrap_angle(float(theta[self.assisted]) + (float(self.plan[j]) if planned else 0.0))
        self.theta_ref.value[...] = self.theta_ref_now

    def update(self, k: int) -> None:
        if self.plan is not None:
            return  # played open loop
        theta, lam = np.asarray(self.theta.value, dtype=float), float(self.lam.value)
        if not (usable_phases(theta) and math.isfinite(lam)):
            self.previous[...] = math.nan
            return
        dt = self.dt * self.every
        rls = self.identifier()
        # nothing is altered before the plan: the phases the group sees are its own
        if usable_phases(self.previous) and rls.observe(self.previous, self.previous, theta, dt):
            self.count += 1
        self.previous[...] = theta
        if self.count >= self.min_ticks and rls.gain_excitation() >= self.min_excitation:
            omega, gain = rls.estimate()
            if np.isfinite(omega).all() and math.isfinite(gain):
                lam = min(max(lam, self.blender.lam_min), self.blender.lam_max)
                self._make_plan(k, theta, lam, omega, gain, dt)

    def _make_plan(self, k: int, theta: np.ndarray, lam: float, omega: np.ndarray, gain: float, dt: float) -> None:
        """Plan ticks k + 1 … the trial's last one from the state predicted for tick k + 1 (nothing altered at k)."""
        if abs(dt - DT) > 1e-12:
            raise RuntimeError(f"PlannedMotion plans on the {DT} s tick of cogblocks.sync.model.DT, not {dt} s")
        n_ticks = round(self.end / DT) + 1 - (k + 1)
        if n_ticks < 1:
            self.plan, self.plan_start = np.zeros(0), k + 1
            return
        start = time.thread_time()
        omega_hat = tuple(float(w) for w in omega)
        model = SyncGroup("identified", self.n, float(gain), omega_hat, self.assisted, self.end, self.adjacency)
        # nothing is altered before the plan: the blender's last alteration is 0
        x_next, _ = tick_model(model, self.adjacency, self.blender)(initial_state(theta, lam, self.blender), 0.0)
        state = np.asarray(x_next, dtype=float).ravel()
        s, states, r = plan_alterations(
            model, self.adjacency, self.blender, state, n_ticks, self.sweeps, max_iter=self.max_iter
        )
        self.plan, self.plan_start = played(states, s, self.n, self.blender), k + 1
        self.predicted = r
        self.plan_ms = (time.thread_time() - start) * 1e3


def checked_sweeps(block: object, sweeps: Any) -> tuple[tuple[float, float, float], ...]:
    """``sweeps`` as (window, tail, knot) triples in s, checked for ``block``'s messages."""
    name = type(block).__name__
    try:
        checked = tuple((float(w), float(t), float(k)) for w, t, k in sweeps)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: sweeps must be (window, tail, knot) triples in s, got {sweeps!r}") from None
    for w, t, k in checked:
        ticks = [round(v / DT) for v in (w, t, k)]
        if not (all(math.isfinite(v) for v in (w, t, k)) and min(ticks[0], ticks[2]) >= 1 and ticks[1] >= 0):
            raise ValueError(f"{name}: a sweep needs window and knot >= {DT} s and tail >= 0, got {(w, t, k)}")
        if ticks[0] % ticks[2] or any(abs(v - n * DT) > 1e-9 for v, n in zip((w, t, k), ticks, strict=True)):
            raise ValueError(
                f"{name}: a sweep's times must be multiples of {DT} s and knot divide window, got {(w, t, k)}"
            )
    return checked
