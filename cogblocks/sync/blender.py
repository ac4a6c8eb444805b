"""The blender of the L2 architecture (section 5.2.2, eqs. 3–6).

``θ_L2 = wrap(θ_L0 + sat_λ(wrap_π(θ_ref − θ_L0)))`` with a threshold λ that
follows ``λ∞ = ψ(e / e_max)(λ_max − λ_min) + λ_min``, ``e = wrap_π(θ_L2 − θ_L0)``,
through the piecewise first-order dynamics of eq. (6), integrated by forward
Euler: fast decrease (κ⁻), slow recovery (κ⁺)."""

from __future__ import annotations

import math

from cogblocks.blocks.angles import TWO_PI, wrap_angle
from cogblocks.blocks.specs import PHASE
from cogblocks.sim import Block, Signal
from cogblocks.sim.params import finite_number, one_of
from cogblocks.sync.stability import check_blender

__all__ = ["Blender", "DELIVERABLE_BLENDER"]

#: The L2 parameters of section 5.2.3.2 (κ⁻ = 2.5 decrease, κ⁺ = 1 increase; see the notes).
DELIVERABLE_BLENDER = {
    "lam_min": 0.3 * math.pi / 2,
    "lam_max": math.pi / 2,
    "e_max": 0.3 * math.pi / 2,
    "kappa_plus": 1.0,
    "kappa_minus": 2.5,
}

_SMOOTH_P = 4.0


def _wrap_pi(x: float) -> float:
    return math.pi - (math.pi - x) % TWO_PI


class Blender(Block):
    """Blend the assisted participant's phase with a reference phase, within a moving limit λ.

    Ports
    -----
    theta_l0 : input, scalar, rad, wrapped
        Phase of the assisted participant.
    theta_ref : input, scalar, rad, wrapped
        Reference phase from the motion computer.
    theta_l2 : output, scalar, rad, wrapped
        Phase displayed by the L2 avatar, in [0, 2π).
    lam : output, scalar, rad
        The threshold λ used at this tick.

    Parameters
    ----------
    lam_min, lam_max : float
        Bounds of λ, with ``0 < lam_min <= lam_max``; λ starts at ``lam_max``.
    e_max : float
        Deviation ``|θ_L2 − θ_L0|`` at which λ∞ reaches ``lam_min`` (> 0).
    kappa_plus, kappa_minus : float
        Rates (1/s) at which λ rises toward λ∞ (``kappa_plus``) and falls
        toward it (``kappa_minus``); both > 0. The deliverable picks
        ``kappa_minus > kappa_plus`` so the limit tightens fast and relaxes slowly.
    saturation : {"hard", "smooth"}
        ``sat_λ`` of eq. (4), or the differentiable ``x / (1 + |x/λ|^4)^(1/4)``.
    psi : {"triangular", "bump"}
        ``ψ(x) = max(0, 1 − |x|)`` or ``exp(1 − 1/(1 − x²))`` for ``|x| < 1``.

    Notes
    -----
    The step must keep the forward-Euler λ dynamics stable: ``dt·κ < 2`` for
    both rates and a stable equilibrium at the limit λ*
    (:func:`cogblocks.sync.check_blender`), or compiling fails;
    ``dt·κ > 1`` makes λ overshoot λ∞ and only warns. Defaults are the
    deliverable's values (:data:`DELIVERABLE_BLENDER`).

    Bad data policy: a non-finite ``theta_l0`` holds the last outputs and does
    not advance λ; a non-finite ``theta_ref`` gives no alteration
    (``θ_L2 = θ_L0``) for that tick.
    """

    def __init__(
        self,
        lam_min: float = DELIVERABLE_BLENDER["lam_min"],
        lam_max: float = DELIVERABLE_BLENDER["lam_max"],
        e_max: float = DELIVERABLE_BLENDER["e_max"],
        kappa_plus: float = DELIVERABLE_BLENDER["kappa_plus"],
        kappa_minus: float = DELIVERABLE_BLENDER["kappa_minus"],
        *,
        saturation: str = "hard",
        psi: str = "triangular",
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        self.lam_min = finite_number(self, "lam_min", lam_min, low=0.0, low_open=True)
        self.lam_max = finite_number(self, "lam_max", lam_max, low=self.lam_min)
        self.e_max = finite_number(self, "e_max", e_max, low=0.0, low_open=True)
        self.kappa_plus = finite_number(self, "kappa_plus", kappa_plus, low=0.0, low_open=True)
        self.kappa_minus = finite_number(self, "kappa_minus", kappa_minus, low=0.0, low_open=True)
        self.saturation = one_of(self, "saturation", saturation, ("hard", "smooth"))
        self.psi = one_of(self, "psi", psi, ("triangular", "bump"))
        self.add_input("theta_l0", PHASE)
        self.add_input("theta_ref", PHASE)
        self.add_output("theta_l2", PHASE)
        self.add_output("lam", Signal(unit="rad"), initial=self.lam_max)
        self.add_state("lam_now", self.lam_max)

    def setup(self) -> None:
        # the λ dynamics must be stable for this step, both along the linear pieces and at the
        # equilibrium where the blender sits at its limit (see cogblocks.sync.stability)
        try:
            check_blender(self, self.dt)
        except ValueError as exc:
            raise self._fail(str(exc).removeprefix("Blender: ")) from None

    def saturate(self, x: float, lam: float) -> float:
        """``sat_λ(x)``: hard clip to [−λ, λ], or its smooth version."""
        if self.saturation == "hard":
            return lam if x > lam else (-lam if x < -lam else x)
        return x / (1.0 + abs(x / lam) ** _SMOOTH_P) ** (1.0 / _SMOOTH_P)

    def psi_of(self, x: float) -> float:
        """``ψ(x)`` of eq. (5), in [0, 1]."""
        ax = abs(x)
        if ax >= 1.0:
            return 0.0
        if self.psi == "triangular":
            return 1.0 - ax
        return math.exp(1.0 - 1.0 / (1.0 - ax * ax))

    def lam_inf(self, e: float) -> float:
        """λ∞ of eq. (5) for a deviation ``e = θ_L2 − θ_L0``."""
        return self.psi_of(e / self.e_max) * (self.lam_max - self.lam_min) + self.lam_min

    def output(self, k: int) -> None:
        theta_l0 = float(self.theta_l0.value)
        if not math.isfinite(theta_l0):
            return
        lam = self.lam_now
        theta_ref = float(self.theta_ref.value)
        shift = self.saturate(_wrap_pi(theta_ref - theta_l0), lam) if math.isfinite(theta_ref) else 0.0
        self.theta_l2.value[...] = wrap_angle(theta_l0 + shift)
        self.lam.value[...] = lam

    def update(self, k: int) -> None:
        # eq. (6), forward Euler, with e from this tick's θ_L2 (the output just written) and θ_L0; computed
        # here rather than kept from output() so that λ_now is the block's whole state between ticks
        theta_l0 = float(self.theta_l0.value)
        if not math.isfinite(theta_l0):
            return  # λ holds on a missing sample, as θ_L2 does
        lam = self.lam_now
        target = self.lam_inf(_wrap_pi(float(self.theta_l2.value) - theta_l0))
        kappa = self.kappa_plus if lam <= target else self.kappa_minus
        self.lam_now = lam - self.dt * kappa * (lam - target)
