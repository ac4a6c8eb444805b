"""Stability and settling of the Blender's threshold dynamics (eqs. 5–6, section 5.2.2).

When the reference stays far from the assisted participant's phase, the blender sits
at its limit: ``e = θ_L2 − θ_L0 = λ`` (hard saturation), so λ∞ becomes a function of
λ itself and the forward-Euler update of eq. (6) is the scalar map

    λ ← λ − dt κ(λ) (λ − λ∞(λ)),   κ = κ⁺ if λ <= λ∞(λ) else κ⁻.

Its fixed point λ* is where λ∞(λ) meets the bisector: the largest alteration the
blender keeps up for long. Below λ*, λ < λ∞ (rate κ⁺); above it, λ > λ∞ (rate κ⁻),
so the map has one multiplier on each side of λ*:

    m± = 1 − dt κ (1 − λ∞'(λ*)),

with the one-sided slope of λ∞ on that side. Since λ∞ decreases in λ, the saturated
regime contracts *faster* than κ alone says, and can oscillate or lose stability
while ``dt κ < 2`` still holds."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from cogblocks.sim.timing import BASE_STEP

if TYPE_CHECKING:  # the blender module imports this one: a run-time import back would be a cycle
    import casadi as ca

    from cogblocks.sync.blender import Blender

__all__ = ["LambdaReport", "check_blender", "lambda_report"]

# What the analysis reads of a Blender: checked by name, since the Blender module imports this one.
_BLENDER_PARAMETERS = ("lam_inf", "lam_min", "lam_max", "e_max", "kappa_plus", "kappa_minus", "psi")
# Grid that brackets λ* before Newton refines it (λ − λ∞(λ) increases, so one sign change).
_BRACKET_POINTS = 65
# Newton tolerance on |λ − λ∞(λ)|, in rad.
_ROOT_TOL = 1e-13


@dataclass(frozen=True)
class LambdaReport:
    """Equilibrium, stability and settling of a Blender's λ dynamics at its limit.

    Attributes
    ----------
    dt : float
        Step of the blender in seconds.
    lam_min, lam_max, e_max, kappa_plus, kappa_minus : float
        The blender's parameters.
    psi : str
        The blender's ψ ("triangular" or "bump").
    lam_star : float
        Equilibrium λ* at the limit: ``λ* = λ∞(λ*)`` with ``e = λ``.
    slope_below, slope_above : float
        One-sided slopes of λ → λ∞(λ) at λ* (from below and from above).
    multiplier_below, multiplier_above : float
        Derivatives of the forward-Euler map at λ* on each side:
        ``1 − dt κ⁺ (1 − slope_below)`` and ``1 − dt κ⁻ (1 − slope_above)``.
    contraction : float
        Asymptotic factor by which ``|λ − λ*|`` shrinks per tick near λ*: the larger
        multiplier, or the geometric mean of both when both are negative (λ then
        alternates sides). Locally stable when below 1.
    tolerance : float
        Fraction of the step defining the settling band (0.02 for 2 %).
    settle_down : float
        Seconds for λ to get, and stay, within ``tolerance · (λ_max − λ*)`` of λ*
        when starting from λ_max with the reference far away (rate κ⁻).
        ``inf`` when it never does.
    settle_up : float
        Seconds for λ to get within ``tolerance · (λ_max − λ*)`` of λ_max when the
        reference comes back onto θ_L0 (e = 0, so λ∞ = λ_max, rate κ⁺), from λ*.
    """

    dt: float
    lam_min: float
    lam_max: float
    e_max: float
    kappa_plus: float
    kappa_minus: float
    psi: str
    lam_star: float
    slope_below: float
    slope_above: float
    multiplier_below: float
    multiplier_above: float
    contraction: float
    tolerance: float
    settle_down: float
    settle_up: float

    @property
    def dt_kappa_plus(self) -> float:
        """``dt · κ⁺``: the linear pieces are stable below 2, monotone up to 1."""
        return self.dt * self.kappa_plus

    @property
    def dt_kappa_minus(self) -> float:
        """``dt · κ⁻``: the linear pieces are stable below 2, monotone up to 1."""
        return self.dt * self.kappa_minus

    @property
    def stable(self) -> bool:
        """``|1 − dt κ±| < 1``: λ converges to any constant λ∞ (``dt κ± < 2``)."""
        return max(self.dt_kappa_plus, self.dt_kappa_minus) < 2.0

    @property
    def monotone(self) -> bool:
        """``dt κ± <= 1``: λ approaches a constant λ∞ without overshoot."""
        return max(self.dt_kappa_plus, self.dt_kappa_minus) <= 1.0

    @property
    def locally_stable(self) -> bool:
        """The saturated equilibrium λ* attracts nearby λ (``contraction < 1``)."""
        return self.contraction < 1.0

    @property
    def locally_monotone(self) -> bool:
        """λ approaches λ* from either side without crossing it (both multipliers >= 0)."""
        return min(self.multiplier_below, self.multiplier_above) >= 0.0

    @property
    def max_stable_dt(self) -> float:
        """Largest step keeping the linear pieces stable: ``2 / max(κ⁺, κ⁻)`` (exclusive)."""
        return 2.0 / max(self.kappa_plus, self.kappa_minus)

    @property
    def max_monotone_dt(self) -> float:
        """Largest step keeping λ monotone everywhere, the saturated equilibrium included."""
        return 1.0 / max(self.kappa_plus * (1.0 - self.slope_below), self.kappa_minus * (1.0 - self.slope_above))

    def __str__(self) -> str:
        def verdict(ok_stable: bool, ok_monotone: bool) -> str:
            if not ok_stable:
                return "UNSTABLE"
            return "stable, monotone" if ok_monotone else "stable, NOT monotone (oscillates)"

        return "\n".join(
            [
                f"Blender λ dynamics at dt = {self.dt:g} s (psi = {self.psi})",
                f"  parameters          λ_min = {self.lam_min:.4f}, λ_max = {self.lam_max:.4f}, "
                f"e_max = {self.e_max:.4f} rad; κ⁺ = {self.kappa_plus:g}, κ⁻ = {self.kappa_minus:g} 1/s",
                f"  equilibrium (e = λ) λ* = {self.lam_star:.6f} rad",
                f"  slope of λ∞ at λ*   {self.slope_below:.4g} below, {self.slope_above:.4g} above",
                f"  linear pieces       dt·κ⁺ = {self.dt_kappa_plus:.4g}, dt·κ⁻ = {self.dt_kappa_minus:.4g}: "
                f"{verdict(self.stable, self.monotone)} (stable below 2, monotone up to 1; "
                f"dt < {self.max_stable_dt:.4g} s)",
                f"  at λ*               multipliers {self.multiplier_below:.6f} below (κ⁺), "
                f"{self.multiplier_above:.6f} above (κ⁻), contraction {self.contraction:.6f}/tick: "
                f"{verdict(self.locally_stable, self.locally_monotone)} "
                f"(monotone for dt <= {self.max_monotone_dt:.4g} s)",
                f"  settling ({100 * self.tolerance:g} %)      {self.settle_down:.4g} s from λ_max down to λ* (κ⁻), "
                f"{self.settle_up:.4g} s from λ* back up to λ_max (κ⁺)",
            ]
        )


def _lam_inf_expr(blender: Blender, lam: ca.SX) -> ca.SX:
    """λ∞ of eq. (5) at e = λ, as a casadi expression: the law of :mod:`cogblocks.sync.blending`."""
    import casadi  # noqa: F401  (loaded on first check, so that importing the blender stays light)

    from cogblocks.sync.blending import BlenderParams, lam_inf

    params = blender if isinstance(blender, BlenderParams) else blender.params
    return lam_inf(lam, params)


def _equilibrium(blender: Blender) -> tuple[float, float, float]:
    """λ* by a casadi Newton root finder, and the one-sided slopes of λ∞ there."""
    import casadi as ca

    lo, hi = blender.lam_min, blender.lam_max
    if hi == lo:
        return lo, 0.0, 0.0
    # λ − λ∞(λ) increases from <= 0 at λ_min to >= 0 at λ_max: bracket, then polish
    grid = np.linspace(lo, hi, _BRACKET_POINTS)
    gaps = np.array([lam - blender.lam_inf(lam) for lam in grid])
    i = min(int(np.searchsorted(gaps, 0.0)), len(grid) - 1)
    if i == 0:
        guess = lo
    else:
        a, b = grid[i - 1], grid[i]
        guess = a - gaps[i - 1] * (b - a) / (gaps[i] - gaps[i - 1])

    lam = ca.SX.sym("lam")
    lam_inf = _lam_inf_expr(blender, lam)
    solver = ca.rootfinder(
        "lambda_star", "newton", {"x": lam, "g": lam - lam_inf}, {"abstol": _ROOT_TOL, "max_iter": 100}
    )
    lam_star = float(solver(guess, []))
    residual = abs(lam_star - blender.lam_inf(lam_star))
    if not residual <= 1e-10:
        raise RuntimeError(f"lambda_report: Newton did not converge (|λ − λ∞(λ)| = {residual:g} at λ = {lam_star})")

    slope = ca.Function("slope", [lam], [ca.jacobian(lam_inf, lam)])
    # evaluate just off λ* so a kink of ψ (the triangular one at e = e_max) shows as two slopes
    delta = 1e-9 * max(1.0, lam_star)
    # + 0.0 turns a flat side's -0.0 into 0.0
    return lam_star, float(slope(lam_star - delta)) + 0.0, float(slope(lam_star + delta)) + 0.0


def _contraction(m_below: float, m_above: float) -> float:
    if m_below < 0.0 and m_above < 0.0:
        # λ alternates sides: two ticks multiply the distance by m_below · m_above
        return math.sqrt(m_below * m_above)
    # a negative multiplier sends λ across once; the other side then contracts alone
    return max(m_below, m_above)


def _ticks_to(ratio: float, r: float) -> float:
    """Smallest n >= 0 with |r|^n <= ratio (inf when |r| >= 1 and ratio < 1)."""
    if ratio >= 1.0:
        return 0
    if r == 0.0:
        return 1
    if abs(r) >= 1.0:
        return math.inf
    return math.ceil(math.log(ratio) / math.log(abs(r)))


def _settle_down_closed_form(blender: Blender, dt: float, lam_star: float, tol: float) -> float:
    """Ticks from λ_max to the band around λ* for the triangular ψ (monotone pieces).

    Above e_max, λ∞ = λ_min and λ − λ_min shrinks by r1 = 1 − dt κ⁻ per tick; below
    e_max, λ∞ is linear in λ and λ − λ* shrinks by r2 = 1 − dt κ⁻ (1 + Δ/e_max).
    """
    lam_min, lam_max, e_max = blender.lam_min, blender.lam_max, blender.e_max
    span = lam_max - lam_min
    band = tol * (lam_max - lam_star)
    r1 = 1.0 - dt * blender.kappa_minus
    r2 = 1.0 - dt * blender.kappa_minus * (1.0 + span / e_max)
    if lam_max <= e_max:
        return _ticks_to(tol, r2)
    if lam_star + band >= e_max:
        return _ticks_to((lam_star + band - lam_min) / span, r1)
    # ticks on the first piece until λ drops below e_max, then the second piece
    n1 = _ticks_to((e_max - lam_min) / span, r1)
    lam_n1 = lam_min + span * r1**n1
    if lam_n1 - lam_star <= band:
        return n1
    return n1 + _ticks_to(band / (lam_n1 - lam_star), r2)


def _settle_down_iterated(blender: Blender, dt: float, lam_star: float, tol: float, contraction: float) -> float:
    """Ticks from λ_max to the band around λ*, by iterating the block's own scalar map."""
    band = tol * (blender.lam_max - lam_star)
    # enough ticks to shrink the error a thousand times below the band at the slower of the
    # rate far from λ* (λ∞ flat) and the rate near it
    n_max = _ticks_to(1e-3 * tol, max(contraction, abs(1.0 - dt * blender.kappa_minus))) + 10
    lam, last_out = blender.lam_max, 0
    for n in range(1, n_max + 1):
        target = blender.lam_inf(lam)
        kappa = blender.kappa_plus if lam <= target else blender.kappa_minus
        lam -= dt * kappa * (lam - target)
        if abs(lam - lam_star) > band:
            last_out = n
    return last_out + 1 if last_out < n_max else math.inf


def lambda_report(blender: Blender, dt: float = BASE_STEP, *, tolerance: float = 0.02) -> LambdaReport:
    """Analyse the λ dynamics of ``blender`` saturated at its limit (``e = λ``).

    Parameters
    ----------
    blender : Blender
        The block (compiled or not); its parameters are read, its state untouched.
    dt : float
        The blender's step in seconds (its period in a diagram).
    tolerance : float
        Settling band as a fraction of the step ``λ_max − λ*`` (2 % by default).

    Returns
    -------
    LambdaReport
        λ* (found by a casadi Newton root finder on ``λ − λ∞(λ)``), the global
        conditions on ``dt κ±``, the multipliers at λ* and the settling times.

    Notes
    -----
    The analysis assumes the hard saturation with ``|wrap_π(θ_ref − θ_L0)| >= λ``, so
    ``e = λ``. With the smooth saturation, e is slightly below λ for any finite
    offset, and the simulated λ settles slightly above λ* (by a relative
    ``(λ/d)⁴ / 4`` for an offset d). Settling times are whole ticks times ``dt``:
    closed form for the triangular ψ when every piece is monotone, otherwise
    iterated with the block's own λ∞. For the triangular ψ,
    ``λ* = (Δ + λ_min) / (1 + Δ/e_max)`` with ``Δ = λ_max − λ_min`` when this lies
    below e_max, else λ_min.
    """
    if not all(hasattr(blender, name) for name in _BLENDER_PARAMETERS):
        raise TypeError(f"lambda_report needs a Blender, got {type(blender).__name__}")
    if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
        raise ValueError(f"lambda_report: dt must be a positive number of seconds, got {dt!r}")
    if not 0.0 < tolerance < 1.0:
        raise ValueError(f"lambda_report: tolerance must be in (0, 1), got {tolerance!r}")
    dt = float(dt)
    lam_star, slope_below, slope_above = _equilibrium(blender)
    m_below = 1.0 - dt * blender.kappa_plus * (1.0 - slope_below)
    m_above = 1.0 - dt * blender.kappa_minus * (1.0 - slope_above)
    contraction = _contraction(m_below, m_above)

    if lam_star == blender.lam_max:
        down = 0
    elif not (contraction < 1.0 and dt * blender.kappa_minus < 2.0):
        down = math.inf
    elif blender.psi == "triangular" and min(m_below, m_above) >= 0.0 and dt * blender.kappa_minus <= 1.0:
        down = _settle_down_closed_form(blender, dt, lam_star, tolerance)
    else:
        down = _settle_down_iterated(blender, dt, lam_star, tolerance, contraction)
    # with e = 0, λ∞ = λ_max whatever ψ: one geometric piece
    up = 0 if lam_star == blender.lam_max else _ticks_to(tolerance, 1.0 - dt * blender.kappa_plus)

    return LambdaReport(
        dt=dt,
        lam_min=blender.lam_min,
        lam_max=blender.lam_max,
        e_max=blender.e_max,
        kappa_plus=blender.kappa_plus,
        kappa_minus=blender.kappa_minus,
        psi=blender.psi,
        lam_star=lam_star,
        slope_below=slope_below,
        slope_above=slope_above,
        multiplier_below=m_below,
        multiplier_above=m_above,
        contraction=contraction,
        tolerance=tolerance,
        settle_down=down * dt,
        settle_up=up * dt,
    )


def check_blender(blender: Blender, dt: float = BASE_STEP) -> LambdaReport:
    """Refuse unstable Blender parameters and warn about non-monotone ones.

    Raises
    ------
    ValueError
        Naming the parameter, when ``dt κ± >= 2`` (λ diverges from any constant
        λ∞) or when the saturated equilibrium λ* is unstable (λ oscillates
        around it for ever although ``dt κ± < 2``).

    Warns
    -----
    RuntimeWarning
        When ``dt κ± > 1`` or a multiplier at λ* is negative: λ overshoots its
        target at each tick.

    Returns
    -------
    LambdaReport
        The report the verdict is based on.
    """
    report = lambda_report(blender, dt)
    rates = {"kappa_plus": report.dt_kappa_plus, "kappa_minus": report.dt_kappa_minus}
    for name, step in rates.items():
        if step >= 2.0:
            raise ValueError(
                f"Blender: dt * {name} = {step:g} >= 2 makes the forward-Euler λ dynamics unstable; "
                f"lower {name} below {2.0 / report.dt:g} 1/s or the step below {2.0 * report.dt / step:g} s"
            )
    sides = {"kappa_plus": report.multiplier_below, "kappa_minus": report.multiplier_above}
    worst = min(sides, key=sides.get)
    if not report.locally_stable:
        raise ValueError(
            f"Blender: the equilibrium at the limit λ* = {report.lam_star:.4g} is unstable: the multipliers "
            f"1 − dt κ (1 − λ∞'(λ*)) are {report.multiplier_below:.4g} (kappa_plus) and "
            f"{report.multiplier_above:.4g} (kappa_minus), so λ oscillates around λ* for ever; lower {worst} "
            "or the step, or raise e_max (λ∞ is steeper the smaller e_max)"
        )
    for name, step in rates.items():
        if step > 1.0:
            warnings.warn(
                f"Blender: dt * {name} = {step:g} > 1: λ overshoots λ∞ at each step (stable but not monotone); "
                "keep it at most 1",
                RuntimeWarning,
                stacklevel=2,
            )
    if not report.locally_monotone:
        warnings.warn(
            f"Blender: at the limit λ oscillates around λ* = {report.lam_star:.4g} while settling (multipliers "
            f"{report.multiplier_below:.4g} below, {report.multiplier_above:.4g} above); lower {worst} or the step",
            RuntimeWarning,
            stacklevel=2,
        )
    return report
