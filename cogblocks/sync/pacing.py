"""A pacing motion computer: every period, the reference that the identified group model predicts best over seconds.

Every ``decide_every`` seconds (a *period*) the block simulates the group it has identified online, with the
blender's λ dynamics in the loop, ``horizon`` seconds ahead for a set of candidate references held over the
whole horizon, all at once (NumPy, forward Euler at a coarse step):

* *none*: θ_ref = θ_L0, which leaves the assisted participant's phase unaltered (the group runs as without L2);
* *mean*: θ_ref = the circular mean of the others' phases (what :class:`MeanPhaseMotion` does), or *gated*:
  only while it is within a gate g of θ_L0, θ_L0 otherwise (altering a participant who is nearly opposite
  the others raises r little but still tightens λ; resting lets λ recover for when they come closer);
* *pace*: θ_ref = φ + ω t, a constant frequency ω on a grid spanning the identified frequencies (and the
  frequency paced now), started from the current reference or from the others' circular mean.

It keeps the candidate with the best predicted time-averaged order parameter, but departs from *none* only
when that prediction beats *none* by ``margin``, and leaves its current choice only for one that beats it by
``switch_margin``: a small predicted gain is within the model's error over a long horizon, and doing nothing is
what cannot lower r. A long horizon is what lets a constant pacing frequency show its worth: it entrains a
group over tens of seconds, which a horizon of a few seconds does not see (docs/validation/sync.md).

The model is identified by :class:`~cogblocks.sync.identification.KuramotoRLS` on the observed phases, θ_L2
rebuilt from the θ_ref the block emitted and the λ it received; no oracle. That identification, the trust in the
model and the decision period are :class:`~cogblocks.sync.identified.PeriodicIdentifyingMotion`'s, and the Euler
step of the predictions is :func:`~cogblocks.sync.identified.euler_step`.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from cogblocks.blocks.angles import wrap_angle, wrap_pi
from cogblocks.sim.params import finite_array, finite_number, one_of, positive_int
from cogblocks.sync.blending import BlenderParams, lam_step
from cogblocks.sync.identification import usable_phases
from cogblocks.sync.identified import MEAN, NONE, PACE, PeriodicIdentifyingMotion, euler_step, margin_choice
from cogblocks.sync.motion import OMEGA_L3_LIMIT

__all__ = ["MEAN", "NONE", "PACE", "PacingMotion", "euler_step", "margin_choice", "predicted_order"]

_MODES = {"none": NONE, "mean": MEAN}


def predicted_order(
    theta: np.ndarray,
    lam: float,
    model: tuple[np.ndarray, float],
    adjacency: np.ndarray,
    assisted: int,
    blender: BlenderParams,
    candidates: tuple[np.ndarray, np.ndarray, np.ndarray],
    *,
    step: float,
    steps: int,
) -> np.ndarray:
    """Mean order parameter (θ_L2 substituted) over ``steps`` Euler steps of ``step`` s, for every candidate.

    Parameters
    ----------
    theta : ndarray, shape (N,)
        The participants' own phases at the start.
    lam : float
        The blender's λ at the start.
    model : (ndarray, float)
        Natural frequencies ω (rad/s) and coupling gain K.
    adjacency : ndarray, shape (N, N)
        ``a_ij`` of the graph.
    assisted : int
        Index of the assisted participant.
    blender : BlenderParams
        The blender the references go through (hard clip, eqs. 3–6).
    candidates : (kinds, values, anchors), each shape (C,)
        Kind of each candidate (:data:`NONE`, :data:`MEAN` or :data:`PACE`); its value: for *pace* the
        frequency (rad/s), for *mean* the gate (rad; π: always the mean); for *pace* the reference's phase at
        the start (anchors are ignored for the other kinds).
    step, steps : float, int
        Euler step (s) and number of steps.

    Returns
    -------
    ndarray, shape (C,)
        The predicted mean of r over steps 0 … steps − 1 (the start included).
    """
    kinds, values, anchors = (np.asarray(c, dtype=float) for c in candidates)
    count = len(kinds)
    theta = np.tile(np.asarray(theta, dtype=float), (count, 1))
    lam = np.full(count, float(lam))
    total = np.zeros(count)
    for s in range(steps):
        theta, lam, r = euler_step(
            theta, lam, model, adjacency, assisted, blender, (kinds, values, anchors), s * step, step
        )
        total += r
    return total / steps


class PacingMotion(PeriodicIdentifyingMotion):
    """Chooses, every period, the reference the identified group model predicts best over a long horizon.

    See the module docstring for the candidates and the choice. Decisions are taken in the update phase of
    ticks ``0, P, 2·P, …`` (``P`` the period in ticks) once the model is trusted, and apply from the next tick.
    Before that (fewer than ``min_ticks`` observed increments, or too little information on the gain:
    :meth:`KuramotoRLS.gain_excitation` below ``min_excitation``) the block does what ``start`` says.

    Parameters
    ----------
    n : int
        Number of participants.
    assisted : int
        0-based index of the assisted participant.
    adjacency : graph spec
        The group's graph (``"ring"``, ``"all"``, ``("random", p, seed)`` or a matrix), known to the block.
    blender : BlenderParams
        The blender the predictions go through (the deliverable's by default).
    decide_every : float
        Seconds per period, a whole number of the block's steps.
    horizon : float
        Seconds simulated per decision.
    step : float
        Largest Euler step (s) of the prediction; smaller when the identified coupling needs it for stability
        (``step · K · max_i Σ_j a_ij ≤ 0.5``), with at most ``max_steps`` steps (a shorter horizon beyond).
    max_steps : int
        Bound on the steps of one prediction (the cost of a decision).
    frequencies : int
        Pacing frequencies on the grid from min(ω̂) − 0.5 to max(ω̂) + 0.5 rad/s.
    gates : sequence of float
        Gates (rad, in (0, π]) of the *mean* candidates; π is the plain circular mean, which ``start="mean"``
        follows.
    margin : float
        Predicted gain in mean r over *none* needed to alter the participant at all.
    switch_margin : float
        Predicted gain over the current choice needed to change it.
    start : {"none", "mean"}
        What the block does before the model is trusted.
    min_ticks : int
        Observed increments before the model is trusted.
    min_excitation : float
        Information on the gain (the least squares' Schur complement) before the model is trusted.

    Notes
    -----
    :attr:`decide_ms` (CPU time of every decision) and :attr:`choices` (the kind chosen at every decision)
    are records since the last reset, not block state. The prediction and the identification use the dense
    N × N graph: the block is meant for groups of up to tens of participants.

    Bad data policy: on a tick with a phase that is not finite and within one turn of [0, 2π), or a
    non-finite λ, nothing is identified or decided (a decision due then is taken at the next good tick), and
    no increment ending or starting there is identified. When pacing, θ_ref keeps integrating the paced
    frequency; otherwise it holds its last value on a tick with a bad phase (a non-finite λ alone does not
    stop it following θ_L0 or the mean). A finite λ outside the blender's [λ_min, λ_max] is clipped to it.
    """

    def __init__(
        self,
        n: int,
        assisted: int,
        *,
        adjacency: Any = "ring",
        blender: BlenderParams | None = None,
        decide_every: float = 1.0,
        horizon: float = 10.0,
        step: float = 0.05,
        max_steps: int = 600,
        frequencies: int = 16,
        gates: Any = (math.pi, 2.0 * math.pi / 3.0, math.pi / 2.0),
        margin: float = 0.005,
        switch_margin: float = 0.002,
        start: str = "none",
        min_ticks: int = 100,
        min_excitation: float = 1.0,
        period: float | None = None,
    ) -> None:
        super().__init__(
            n,
            assisted,
            period,
            adjacency,
            blender,
            decide_every=decide_every,
            step=step,
            min_ticks=min_ticks,
            min_excitation=min_excitation,
        )
        self.horizon = finite_number(self, "horizon", horizon, low=0.0, low_open=True)
        self.max_steps = positive_int(self, "max_steps", max_steps)
        self.frequencies = positive_int(self, "frequencies", frequencies, minimum=2)
        self.gates = finite_array(self, "gates", gates, ndim=1)
        if not (len(self.gates) and np.all((self.gates > 0.0) & (self.gates <= math.pi))):
            raise ValueError(f"PacingMotion: gates must be one or more angles in (0, π], got {gates!r}")
        self.margin = finite_number(self, "margin", margin, low=0.0)
        self.switch_margin = finite_number(self, "switch_margin", switch_margin, low=0.0)
        self.start = _MODES[one_of(self, "start", start, tuple(_MODES))]
        self.others = np.arange(n) != self.assisted
        self.add_state("mode", self.start)
        self.add_state("value", math.pi)  # the paced frequency, or the mean's gate
        self.add_state("theta_ref_now", 0.0)
        self.decide_ms: list[float] = []
        self.choices: list[int] = []

    def reset(self) -> None:
        super().reset()
        self.decide_ms, self.choices = [], []

    def _reference(self, theta: np.ndarray) -> float:
        """θ_ref of this tick for the current mode (``theta`` usable)."""
        if self.mode == PACE:
            return float(self.theta_ref_now)
        l0 = float(theta[self.assisted])
        if self.mode == MEAN:
            others = theta[self.others]
            centre = math.atan2(np.sin(others).sum(), np.cos(others).sum())
            if abs(float(wrap_pi(centre - l0))) <= self.value:
                return wrap_angle(centre)
        return l0

    def output(self, k: int) -> None:
        theta = np.asarray(self.theta.value, dtype=float)
        if self.mode == PACE or usable_phases(theta):
            self.theta_ref.value[...] = self._reference(theta)

    def update(self, k: int) -> None:
        theta, lam = np.asarray(self.theta.value, dtype=float), float(self.lam.value)
        dt = self.dt * self.every
        if k % self.decide_ticks == 0:
            self.due = True
        if not (usable_phases(theta) and math.isfinite(lam)):
            self.previous[...] = math.nan
        else:
            lam = min(max(lam, self.blender.lam_min), self.blender.lam_max)
            ref = self._reference(theta)
            seen = self._identify(theta, lam, ref, dt)
            model = self.model() if self.due else None
            if model is not None:
                self._decide(theta, seen, lam, ref, model)
                self.due = False
                return
        if self.mode == PACE:
            self.theta_ref_now = wrap_angle(self.theta_ref_now + dt * self.value)

    def candidates(self, theta_next: np.ndarray, ref: float, omega: np.ndarray, dt: float) -> tuple[np.ndarray, ...]:
        """(kinds, values, phases at the next tick) of the candidates: *none*, the *mean*s (one per gate), *pace*s.

        When pacing, the first *pace* candidate continues at the paced frequency from the current reference.
        """
        grid = np.linspace(np.min(omega) - 0.5, np.max(omega) + 0.5, self.frequencies)
        if self.mode == PACE:
            grid = np.r_[self.value, grid]
        grid = np.clip(grid, -OMEGA_L3_LIMIT, OMEGA_L3_LIMIT)
        others = theta_next[self.others]
        centre = math.atan2(np.sin(others).sum(), np.cos(others).sum())
        m, g = len(grid), len(self.gates)
        kinds = np.r_[NONE, np.full(g, MEAN), np.full(2 * m, PACE)]
        values = np.r_[0.0, self.gates, grid, grid]
        anchors = np.r_[np.zeros(1 + g), ref + dt * grid, np.full(m, centre)]
        return kinds, values, anchors

    def plan(
        self, theta: np.ndarray, seen: np.ndarray, lam: float, ref: float, model: tuple[np.ndarray, float]
    ) -> tuple[int, tuple[np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
        """One decision on this tick's phases, θ̃ and λ, the reference emitted and the model ``(ω, K)``.

        Returns
        -------
        (int, (kinds, values, anchors), ndarray)
            The chosen candidate's index, the candidates (see :meth:`candidates`) and their predicted mean r.
        """
        omega, gain = model
        b, dt = self.blender, self.dt * self.every
        # this tick's θ̃ and λ are already fixed: advance them once (as the plant will), then fan out
        pull = np.cos(seen) * (self.adjacency @ np.sin(seen)) - np.sin(seen) * (self.adjacency @ np.cos(seen))
        theta_next = theta + dt * (omega + gain * pull)
        e = abs(float(wrap_pi(seen[self.assisted] - theta[self.assisted])))
        lam_next = lam_step(lam, e, b, dt)
        step = self._stable_step(gain)
        steps = min(self.max_steps, max(1, round(self.horizon / step)))
        cands = self.candidates(theta_next, ref, omega, dt)
        scores = predicted_order(
            theta_next, lam_next, model, self.adjacency, self.assisted, b, cands, step=step, steps=steps
        )
        return self._best(cands[0], scores), cands, scores

    def _best(self, kinds: np.ndarray, scores: np.ndarray) -> int:
        """The candidate chosen with the margins: over *none* (``margin``) and over the current choice."""
        if self.mode == MEAN:
            current = 1 + int(np.argmin(np.abs(self.gates - self.value)))
        else:  # pacing: the first pace candidate continues it
            current = 0 if self.mode == NONE else 1 + len(self.gates)
        return margin_choice(kinds, scores, current, self.margin, self.switch_margin)

    def _decide(
        self, theta: np.ndarray, seen: np.ndarray, lam: float, ref: float, model: tuple[np.ndarray, float]
    ) -> None:
        """Plan, and switch to the chosen candidate from the next tick on."""
        start = time.thread_time()
        best, (kinds, values, anchors), _ = self.plan(theta, seen, lam, ref, model)
        self.mode, self.value = int(kinds[best]), float(values[best])
        if self.mode == PACE:
            self.theta_ref_now = wrap_angle(float(anchors[best]))
        self.choices.append(self.mode)
        self.decide_ms.append((time.thread_time() - start) * 1e3)
