"""Algorithm 1 of section 5.2.2: phase and half-amplitudes of a 1D oscillation, sample by sample."""

from __future__ import annotations

import math

import numpy as np
import scipy.signal

from cogblocks.blocks.angles import TWO_PI, wrap_angle
from cogblocks.blocks.specs import FLAG, PHASE
from cogblocks.phase.gate import NUMERIC_LIMIT
from cogblocks.phase.oscillation_model import OscillationModel
from cogblocks.phase.transient import GapTransient
from cogblocks.sim import Block
from cogblocks.sim.params import finite_number, positive_int

__all__ = ["Algorithm1Phase"]

_ROUNDING = 1e-9  # relative size below which a centred position or velocity is rounding noise
_SIGNIFICANT = 0.3  # share of the last amplitude of its kind an extremum must reach (velocity chatter near the centre)
_DOUBT = tuple(0.125 * j for j in range(-4, 5))  # rad: the phase's own error, which rule (b) allows for


class Algorithm1Phase(OscillationModel, Block):
    """Phase and half-amplitudes of a 1D oscillation, sample by sample (Algorithm 1).

    The leaf of :class:`PhaseEstimator`: it expects an already low-passed position. Each tick it

    1. centres the position with a causal running mean over the last ``centre_periods`` estimated
       periods (over every sample seen so far until a period is known); a whole number of periods
       cancels the oscillation itself, which a fixed window in seconds does not (see the docs);
    2. takes the velocity ``v`` and the acceleration ``a`` as backward differences, ``a`` over
       ``accel_window`` seconds: ``a_t = (v_t − v_{t−m}) / (m dt)``;
    3. updates the four half-amplitudes on the events of Algorithm 1 (sign convention of the
       algorithm notes): ``A_v+ ← |v|`` on an upward zero crossing with ``v > 0``, ``A_v− ← |v|`` on a
       downward one with ``v < 0``, ``A_p+ ← |p|`` when ``v`` turns from ``≥ 0`` to ``< 0`` with
       ``a < 0`` (a maximum), ``A_p− ← |p|`` when ``v`` turns from ``< 0`` to ``≥ 0`` with ``a > 0``
       (a minimum). Two guards that the algorithm's own assumption (maxima and minima alternate)
       justifies: an extremum counts only well on its own side of the centre (``p > 0.3 A_p+`` for
       a maximum: a share of the running amplitude, so in any unit), and only after one of the other
       kind (velocity chatter at an extremum would otherwise give
       a second one a few samples later, and a period of a few samples);
    4. estimates the frequency from the interval between two maxima or two minima (a frequency
       not re-measured for 3 periods counts as stale for the drop-out rule (a) below);
    5. outputs ``θ = atan2(−v / A_v±, p / A_p±) + lead`` wrapped to ``[0, 2π)``, each amplitude chosen
       by the sign of ``p`` or ``v``; ``p = cos ωt`` gives ``θ = ωt``. ``lead`` is the phase lag,
       at the estimated frequency, of the Butterworth filter in front (when ``cutoff`` is given)
       plus a quarter step for the backward-difference velocity: the filter's lag would otherwise
       be a phase error of 0.2-0.6 rad at 0.4-1.2 Hz with a 3 Hz cut-off.

    With a one-sample acceleration the check of step 3 is void (a sign change of ``v`` always comes
    with an acceleration of the matching sign). Over ``m`` samples it rejects a zero-velocity point
    reached from the wrong side: an inflection plateau in mid-swing, where ``v`` touches zero and
    the movement carries on in the same direction with a positive acceleration over the window.
    After the two guards above it seldom decides anything (it changes no figure of the benchmark);
    it matters when the alternation restarts, at start-up and after a drop-out.

    Ports
    -----
    p : input, scalar, ``unit``
        The low-passed position.
    raw : input, scalar, ``unit``
        The unfiltered position, read only to tell valid, missing and frozen samples apart (the
        low-pass filter in front hides both).
    v, a : input, scalar, ``unit``/s and ``unit``/s^2 (only with ``derivative_inputs=True``)
        Velocity and acceleration estimated in front (a Kalman filter's ``v_hat`` and ``a_hat``),
        used instead of the backward differences of step 2; a tick where ``p``, ``v`` or ``a`` is
        not finite is skipped like a non-finite ``raw``.
    theta : output, scalar, rad, wrapped
        Estimated phase in ``[0, 2π)``.
    amp_p : output, shape (2,), ``unit``
        ``[A_p+, A_p−]``: the last maximum and the magnitude of the last minimum of the centred position.
    amp_v : output, shape (2,), ``unit``/s
        ``[A_v+, A_v−]``: the speed at the last upward and at the last downward zero crossing.

    held : output, scalar bool
        True when ``theta`` is extrapolated (or held) rather than measured: on a missing sample, in a
        confirmed drop-out and during the hold-off after one.
    settled : output, scalar bool
        True once every half-amplitude and a period are measured (the first one to two periods are not).

    Parameters
    ----------
    unit : str
        Unit of the position (``"mm"`` by default; any unit works, no threshold is absolute);
        velocities are in ``unit + "/s"``.
    centre_periods : int
        Length of the centring window, in estimated periods (>= 1).
    accel_window : float
        Span in seconds of the backward difference that gives the acceleration of the check
        (>= 0; rounded to a whole number of steps, at least two; 0 gives one step).
    min_dropout : float
        Shortest run of exactly repeated ``raw`` samples that may be a drop-out, in seconds (>= 0;
        rounded to whole steps, at least two repeats). The run must also be implausible, see below.
    dropout_period : float
        Rule (a) of a drop-out, in estimated periods (> 0): a run of repeats longer than this
        fraction of the period (of ``max_period`` until a period is known). 0.25 by default: a
        quantised sensor repeats at an extremum for ``2 √(2 q / A) / ω``, 0.1 period for a step
        ``q`` of 5 % of the amplitude ``A``.
    dropout_steps : float
        Rule (b), in quantisation steps (> 0): a run of ``r`` repeats is a drop-out once the
        oscillation, followed from the run's first phase ``θ₀`` at the estimated frequency, would
        have spanned more than this many steps ``q``: ``Ā · range(cos, [θ₀, θ₀ + r ω dt]) > 3 q``
        with ``Ā`` the mean position amplitude, for the least favourable ``θ₀`` within ±0.5 rad of
        the estimate (the estimate's own error). So a repeat is implausible in mid-swing and
        normal at an extremum. ``q`` is measured online: the smallest non-zero difference between
        two samples seen so far (it tends to 0 on an unquantised signal, where any exact repeat
        is suspicious). A quantised signal stays on one value while it spans less than one step.
    holdoff : float
        Seconds after a drop-out during which the phase keeps coasting and no amplitude is updated,
        while the low-pass filter in front settles (>= 0; never longer than the drop-out itself).
    max_coast : float
        Longest extrapolation, in estimated periods (> 0): beyond it the phase holds.
    max_period : float
        Longest period in seconds that is tracked (> 0): it sizes the centring buffer, and a
        longer interval between two maxima (or minima) is a pause, not a period.
    cutoff : float, optional
        Cut-off in Hz of the Butterworth low-pass in front of the block, whose lag is compensated
        (see step 5); ``None`` (the default) compensates nothing.
    order : int
        Order of that filter (>= 1).
    derivative_inputs : bool
        Read the velocity and the acceleration from the inputs ``v`` and ``a`` (declared only then)
        instead of differencing ``p``; ``accel_window`` is then unused.

    Notes
    -----
    Bad data policy.

    * Before an amplitude is known (no event of its kind yet) it is the largest magnitude of its
      signal seen so far on its half (a provisional amplitude); while that is 0, or below 1e-9 of
      the position's magnitude (the filter's rounding noise), the normalised value is 0. So the
      phase is 0 on an all-zero or constant input and never NaN.
    * A missing sample (NaN or inf ``raw`` or input, or beyond 1e150 in magnitude, which no unit
      makes a measurement) advances no state of the algorithm: ``theta`` is extrapolated from the
      last measured phase at the last estimated frequency, ``held`` is True, amplitudes hold, and
      no period is measured across the gap.
    * A drop-out is a run of exactly repeated ``raw`` samples at least ``min_dropout`` long that is
      implausible for this signal: rule (a) or (b) above. From the tick it is confirmed, the phase
      is extrapolated from the run's first sample (so the unconfirmed repeats are rewound), no
      amplitude is updated, the centring window is filled with the extrapolated oscillation (so
      that it still spans whole periods) and no period is measured across it; this goes on for
      ``holdoff`` seconds after it ends (at most as long as it lasted), with ``held`` True.
    * Extrapolation runs at the last estimated frequency for at most ``max_coast`` periods, then
      the phase holds; before any frequency is known it holds.
    """

    def __init__(
        self,
        *,
        unit: str = "mm",
        centre_periods: int = 2,
        accel_window: float = 0.05,
        min_dropout: float = 0.03,
        dropout_period: float = 0.25,
        dropout_steps: float = 3.0,
        holdoff: float = 0.2,
        max_coast: float = 2.0,
        max_period: float = 5.0,
        cutoff: float | None = None,
        order: int = 2,
        derivative_inputs: bool = False,
        remove_transient: bool = False,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        if not isinstance(derivative_inputs, (bool, np.bool_)):
            raise ValueError(
                f"{type(self).__name__}: derivative_inputs must be True or False, got {derivative_inputs!r}"
            )
        self.derivative_inputs = bool(derivative_inputs)
        if not isinstance(remove_transient, (bool, np.bool_)):
            raise ValueError(f"{type(self).__name__}: remove_transient must be True or False, got {remove_transient!r}")
        if remove_transient and (cutoff is None or self.derivative_inputs):
            raise ValueError(f"{type(self).__name__}: remove_transient needs a cutoff and no derivative_inputs")
        self.remove_transient = bool(remove_transient)
        if not isinstance(unit, str) or not unit:
            raise ValueError(f"{type(self).__name__}: unit must be a non-empty string, got {unit!r}")
        self.centre_periods = positive_int(self, "centre_periods", centre_periods)
        self.accel_window = finite_number(self, "accel_window", accel_window, low=0.0)
        self.min_dropout = finite_number(self, "min_dropout", min_dropout, low=0.0)
        self.dropout_period = finite_number(self, "dropout_period", dropout_period, low=0.0, low_open=True)
        self.dropout_steps = finite_number(self, "dropout_steps", dropout_steps, low=0.0, low_open=True)
        self.holdoff = finite_number(self, "holdoff", holdoff, low=0.0)
        self.max_coast = finite_number(self, "max_coast", max_coast, low=0.0, low_open=True)
        self.max_period = finite_number(self, "max_period", max_period, low=0.0, low_open=True)
        self.cutoff = None if cutoff is None else finite_number(self, "cutoff", cutoff, low=0.0, low_open=True)
        self.order = positive_int(self, "order", order)
        self.add_input("p", shape=(), unit=unit)
        self.add_input("raw", shape=(), unit=unit)
        if self.derivative_inputs:
            self.add_input("v", shape=(), unit=f"{unit}/s")
            self.add_input("a", shape=(), unit=f"{unit}/s^2")
        self.add_output("theta", PHASE)
        self.add_output("amp_p", shape=(2,), unit=unit)
        self.add_output("amp_v", shape=(2,), unit=f"{unit}/s")
        self.add_output("held", FLAG)
        self.add_output("settled", FLAG)
        self.add_state("primed", False)
        self.add_state("raw_prev", 0.0)
        self.add_state("repeats", 0)  # how many samples in a row repeated raw_prev exactly
        self.add_state("step", math.inf)  # quantisation step: the smallest non-zero change of raw seen
        self.add_state("run_phase", 0.0)  # phase at the first sample of the current run of repeats
        self.add_state("p_prev", 0.0)  # filtered position
        self.add_state("pc_prev", 0.0)  # centred position
        self.add_state("v_prev", 0.0)
        self.add_state("v_hist", np.zeros(1))  # the last m velocities, a ring
        self.add_state("v_pos", 0)
        self.add_state("csum", np.zeros(2))  # cumulative sums of the pushed positions, a ring
        self.add_state("n_pushed", 0)
        self.add_state("total", 0.0)
        self.add_state("amp", np.zeros(4))  # A_p+, A_p-, A_v+, A_v-
        self.add_state("known", np.zeros(4, dtype=bool))
        self.add_state("last_extremum", 0)  # +1 after a maximum, -1 after a minimum, 0 at the start
        self.add_state("t_max", -1.0)  # time of the last accepted maximum, -1 = none
        self.add_state("t_min", -1.0)
        self.add_state("omega", 0.0)  # estimated angular frequency, 0 = unknown
        self.add_state("t_period", 0.0)  # when omega was last measured
        self.add_state("lead", 0.0)  # lag of the filtering in front at omega, added to the phase
        self.add_state("phase", 0.0)
        self.add_state("anchor", 0.0)  # the last measured phase, which extrapolation starts from
        self.add_state("since", 0)  # ticks since it
        self.add_state("coast", 0)  # ticks left of the hold-off after a drop-out
        self.add_state("gap_z", np.zeros((1, 2)))  # state of the filter's response to a drop-out (remove_transient)
        self.add_state("gap_z_run", np.zeros((1, 2)))  # that state when the current run of repeats began
        self.add_scratch("_pending", None)  # what output() decided, committed by update()

    def setup(self) -> None:
        self._m = 1 if self.accel_window == 0.0 else max(2, round(self.accel_window / self.dt))
        self._min_repeats = max(2, round(self.min_dropout / self.dt))
        self._sos = None
        if self.cutoff is not None:
            if self.cutoff >= 0.5 / self.dt:
                raise self._fail(f"cutoff {self.cutoff} Hz must be below the Nyquist frequency {0.5 / self.dt:g} Hz")
            self._sos = scipy.signal.butter(self.order, self.cutoff, fs=1.0 / self.dt, output="sos").tolist()
        self._transient = GapTransient(self._sos) if self.remove_transient else None
        if self._transient is not None:
            self.add_state("gap_z", self._transient.rest())
            self.add_state("gap_z_run", self._transient.rest())
        self._holdoff_ticks = round(self.holdoff / self.dt)
        self._size = round(self.centre_periods * self.max_period / self.dt) + 1
        self.add_state("v_hist", np.zeros(self._m))
        self.add_state("csum", np.zeros(self._size))

    def _sample(self) -> tuple[float, float, float, float] | None:
        """``raw, p, v, a`` of this tick, or None when the sample is missing."""
        values = [float(self.raw.value), float(self.p.value)]
        if self.derivative_inputs:
            values += [float(self.v.value), float(self.a.value)]
        if not all(math.isfinite(x) and abs(x) < NUMERIC_LIMIT for x in values):
            return None
        return (values + [0.0, 0.0])[:4] if not self.derivative_inputs else tuple(values)

    def output(self, k: int) -> None:
        sample = self._sample()
        if sample is None:  # missing: extrapolate, advance nothing else (but the filter's reconstruction)
            since = self.since + 1
            phase = self._extrapolate(self.anchor, since)
            self.theta.value[...] = phase
            self.held.value[...] = True
            self.settled.value[...] = bool(self.known.all()) and self.omega > 0.0
            self._pending = ("missing", phase, since, min(self._holdoff_ticks, since), self._fill_gap(phase))
            return
        raw, pf, v_in, a_in = sample
        dt = self.dt
        primed = self.primed
        repeats = self.repeats + 1 if primed and raw == self.raw_prev else 0
        step = self.step
        if primed and repeats == 0 and raw != self.raw_prev:
            step = min(step, abs(raw - self.raw_prev))
        run_phase = self.phase if repeats == 1 else self.run_phase
        t = (k // self.every) * dt
        period = TWO_PI / self.omega if self.omega > 0.0 else self.max_period
        if t - self.t_period > 3.0 * period:  # stale: rule (a) must not keep the period from being measured again
            period = self.max_period
        frozen = repeats >= self._min_repeats and (
            repeats * dt > self.dropout_period * period
            or 0.5 * (self.amp[0] + self.amp[1]) * min(_swing(run_phase + d, self.omega * dt * repeats) for d in _DOUBT)
            > self.dropout_steps * step
        )
        coasting = frozen or self.coast > 0
        anchor, since = self.anchor, self.since
        if frozen and self.since < repeats:  # just confirmed: the whole run is the drop-out
            anchor, since = run_phase, repeats
        elif coasting:
            since += 1
        phase = self._extrapolate(anchor, since) if coasting else 0.0
        gap_z, gap_z_run = self.gap_z, self.gap_z_run
        if self._transient is not None and primed:
            if repeats == 1:
                gap_z_run = gap_z
            if frozen and self.since < repeats:  # just confirmed: the filter was fed the frozen value all along
                gap = (self._movement(self._extrapolate(anchor, j)) - raw for j in range(1, repeats + 1))
                response, gap_z = self._transient.run(gap_z_run, gap)
            else:
                response, gap_z = self._transient.step(gap_z, self._movement(phase) - raw if frozen else 0.0)
            pf += response
        x = pf
        if frozen:
            # keep the centring window a whole number of periods: fill it with the coasting oscillation
            x = self._movement(phase - self.lead)
        n_pushed = self.n_pushed + 1
        total = self.total + x
        pc = self._centred(pf, n_pushed, total)
        if self.derivative_inputs:
            v, a = v_in, a_in
        else:
            v = (pf - self.p_prev) / dt if primed else 0.0
            a = (v - self.v_hist[self.v_pos]) / (self._m * dt)
        amp = self.amp.copy()
        known = self.known.copy()
        last, t_max, t_min, omega, lead = self.last_extremum, self.t_max, self.t_min, self.omega, self.lead
        t_period = self.t_period
        if primed and not coasting:
            pc_prev, v_prev = self.pc_prev, self.v_prev
            if pc_prev < 0.0 <= pc and v > 0.0:
                amp[2], known[2] = v, True
            if pc_prev >= 0.0 > pc and v < 0.0:
                amp[3], known[3] = -v, True
            if v_prev >= 0.0 > v and a < 0.0 and pc > _SIGNIFICANT * amp[0] and last != 1:
                amp[0], known[0], last = pc, True, 1
                omega = self._frequency(t - t_max if t_max >= 0.0 else 0.0, omega)
                t_max = t
            if v_prev < 0.0 <= v and a > 0.0 and -pc > _SIGNIFICANT * amp[1] and last != -1:
                amp[1], known[1], last = -pc, True, -1
                omega = self._frequency(t - t_min if t_min >= 0.0 else 0.0, omega)
                t_min = t
            if omega != self.omega:
                lead = self._lag(omega)
                t_period = t
            # provisional amplitudes: the largest magnitude seen so far on each half
            half = 0 if pc >= 0.0 else 1
            if not known[half]:
                amp[half] = max(amp[half], abs(pc))
            half = 2 if v >= 0.0 else 3
            if not known[half]:
                amp[half] = max(amp[half], abs(v))
        if not coasting:
            a_p = amp[0] if pc >= 0.0 else amp[1]
            a_v = amp[2] if v >= 0.0 else amp[3]
            tiny = _ROUNDING * abs(pf)  # amplitudes at the rounding level of the filter count as none
            v_norm = v / a_v if a_v > tiny / dt else 0.0
            p_norm = pc / a_p if a_p > tiny else 0.0
            phase = wrap_angle(math.atan2(-v_norm, p_norm) + lead)
            anchor, since = phase, 0
        if frozen:
            coast = min(self._holdoff_ticks, since)
        else:
            coast = max(0, self.coast - 1)
        if frozen or self.since and not coasting:
            t_max = t_min = -1.0  # no period may span a drop-out or a gap
            last = 0
        self.theta.value[...] = phase
        self.amp_p.value[...] = amp[:2]
        self.amp_v.value[...] = amp[2:]
        self.held.value[...] = coasting
        self.settled.value[...] = bool(known.all()) and omega > 0.0
        self._pending = (
            (raw, repeats, step, run_phase, pf, pc, v, n_pushed, total),
            (amp, known, last, t_max, t_min, omega, t_period, lead, phase, anchor, since, coast),
            (gap_z, gap_z_run),
        )

    def update(self, k: int) -> None:
        pending = self._pending
        if pending is None:
            return
        if pending[0] == "missing":
            _, self.phase, self.since, self.coast, filled = pending
            if filled is not None:
                self.gap_z, self.p_prev, self.pc_prev, self.v_prev, self.n_pushed, self.total = filled
                self.csum[self.n_pushed % self._size] = self.total
                self.v_hist[self.v_pos] = self.v_prev
                self.v_pos = (self.v_pos + 1) % self._m
            return
        raw, repeats, step, run_phase, pf, pc, v, n_pushed, total = pending[0]
        amp, known, last, t_max, t_min, omega, self.t_period, lead, phase, anchor, since, coast = pending[1]
        self.primed = True
        self.raw_prev, self.repeats, self.step, self.p_prev, self.pc_prev, self.v_prev = raw, repeats, step, pf, pc, v
        self.run_phase = run_phase
        self.v_hist[self.v_pos] = v
        self.v_pos = (self.v_pos + 1) % self._m
        self.csum[n_pushed % self._size] = total
        self.n_pushed, self.total = n_pushed, total
        self.amp[...] = amp
        self.known[...] = known
        self.last_extremum, self.t_max, self.t_min, self.omega, self.lead = last, t_max, t_min, omega, lead
        self.phase, self.anchor, self.since, self.coast = phase, anchor, since, coast
        self.gap_z, self.gap_z_run = pending[2]


def _swing(start: float, span: float) -> float:
    """Range (max − min) of ``cos`` over ``[start, start + span]``: how far a unit oscillation moves in that stretch."""
    if span >= TWO_PI:
        return 2.0
    ends = (math.cos(start), math.cos(start + span))
    high = 1.0 if math.floor((start + span) / TWO_PI) > math.floor(start / TWO_PI) else max(ends)
    low = -1.0 if math.floor((start + span - math.pi) / TWO_PI) > math.floor((start - math.pi) / TWO_PI) else min(ends)
    return high - low
