"""The blender of the L2 architecture (section 5.2.2, eqs. 3–6).

``θ_L2 = wrap(θ_L0 + sat_λ(wrap_π(θ_ref − θ_L0)))`` with a threshold λ that
follows ``λ∞ = ψ(e / e_max)(λ_max − λ_min) + λ_min``, ``e = wrap_π(θ_L2 − θ_L0)``,
through the piecewise first-order dynamics of eq. (6), integrated by forward
Euler: fast decrease (κ⁻), slow recovery (κ⁺). The continuous option unwraps the
difference and limits the alteration's rate, so that the avatar never jumps
(:mod:`cogblocks.sync.blending` holds the law, shared with every model that plans
through it)."""

from __future__ import annotations

import math
import warnings
from dataclasses import asdict, replace
from typing import Any

import numpy as np

from cogblocks.blocks.angles import TWO_PI, wrap_angle
from cogblocks.blocks.specs import PHASE
from cogblocks.sim import Block, Signal
from cogblocks.sim.params import finite_number, one_of
from cogblocks.sync.blending import DELIVERABLE, BlenderParams, alteration, lam_inf, lam_step
from cogblocks.sync.stability import check_blender

__all__ = ["Blender"]


def __getattr__(name: str) -> Any:
    if name == "DELIVERABLE_BLENDER":
        warnings.warn(
            "DELIVERABLE_BLENDER is deprecated: use cogblocks.sync.DELIVERABLE, a BlenderParams "
            "(dataclasses.asdict(DELIVERABLE) gives its fields as a dict)",
            DeprecationWarning,
            stacklevel=2,
        )
        return {k: getattr(DELIVERABLE, k) for k in ("lam_min", "lam_max", "e_max", "kappa_plus", "kappa_minus")}
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _given(value: Any, default: Any) -> bool:
    """Whether a keyword was given beside ``params``: a value other than its default (False is not 0 here)."""
    return value is not default if isinstance(default, bool) or default is None else value != default


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
    continuous : bool
        Unwrap θ_ref − θ_L0 around the last alteration: the alteration keeps its side
        when the difference crosses ±π, instead of flipping from +λ to −λ in one tick.
    slew : float or None
        Largest rate of change of the alteration θ_L2 − θ_L0 (rad/s); ``None``: unlimited.
    params : BlenderParams, optional
        All of the above as one object (:data:`cogblocks.sync.blending.CONTINUOUS`, say);
        then no other parameter may be given.

    Attributes
    ----------
    params : BlenderParams
        The parameters as one object: what the motion computers plan through.

    Notes
    -----
    The step must keep the forward-Euler λ dynamics stable: ``dt·κ < 2`` for
    both rates and a stable equilibrium at the limit λ*
    (:func:`cogblocks.sync.check_blender`), or compiling fails;
    ``dt·κ > 1`` makes λ overshoot λ∞ and only warns. Defaults are the
    deliverable's values (:data:`~cogblocks.sync.blending.DELIVERABLE`), with its memoryless law.

    Bad data policy: a non-finite ``theta_l0`` holds the last outputs and does
    not advance λ; a non-finite ``theta_ref`` asks for no alteration
    (``θ_L2 = θ_L0`` with the deliverable's law; the continuous one slews toward it).
    In a batch (the block runs one at once) this holds run by run.
    """

    batchable = True

    def __init__(
        self,
        lam_min: float = DELIVERABLE.lam_min,
        lam_max: float = DELIVERABLE.lam_max,
        e_max: float = DELIVERABLE.e_max,
        kappa_plus: float = DELIVERABLE.kappa_plus,
        kappa_minus: float = DELIVERABLE.kappa_minus,
        *,
        saturation: str = "hard",
        psi: str = "triangular",
        continuous: bool = False,
        slew: float | None = None,
        params: BlenderParams | None = None,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        values = {
            "lam_min": lam_min,
            "lam_max": lam_max,
            "e_max": e_max,
            "kappa_plus": kappa_plus,
            "kappa_minus": kappa_minus,
            "saturation": saturation,
            "psi": psi,
            "continuous": continuous,
            "slew": slew,
        }
        if params is not None:
            if not isinstance(params, BlenderParams):
                raise ValueError(f"Blender: params must be a BlenderParams, got {type(params).__name__}")
            given = [name for name, value in values.items() if _given(value, getattr(DELIVERABLE, name))]
            if given:
                raise ValueError(f"Blender: give params or {given}, not both")
            values = {name: getattr(params, name) for name in values}
        self.lam_min = finite_number(self, "lam_min", values["lam_min"], low=0.0, low_open=True)
        self.lam_max = finite_number(self, "lam_max", values["lam_max"], low=self.lam_min)
        for name in ("e_max", "kappa_plus", "kappa_minus"):
            setattr(self, name, finite_number(self, name, values[name], low=0.0, low_open=True))
        self.saturation = one_of(self, "saturation", values["saturation"], ("hard", "smooth"))
        self.psi = one_of(self, "psi", values["psi"], ("triangular", "bump"))
        if not isinstance(values["continuous"], bool):
            raise ValueError(f"Blender: continuous must be True or False, got {values['continuous']!r}")
        self.continuous = values["continuous"]
        slew = values["slew"]
        self.slew = None if slew is None else finite_number(self, "slew", slew, low=0.0, low_open=True)
        self.params = BlenderParams(**{name: getattr(self, name) for name in values})
        self._memoryless = replace(self.params, continuous=False, slew=None)
        self.add_input("theta_l0", PHASE)
        self.add_input("theta_ref", PHASE)
        self.add_output("theta_l2", PHASE)
        self.add_output("lam", Signal(unit="rad"), initial=self.lam_max)
        self.add_state("lam_now", self.lam_max)
        self.add_state("shift_now", 0.0)  # the alteration θ_L2 − θ_L0 of the last tick (the continuous law's memory)

    def setup(self) -> None:
        lead = self.batch_shape  # λ and the last alteration, one per run of a batch
        self.add_state("lam_now", np.full(lead, self.lam_max) if lead else self.lam_max)
        self.add_state("shift_now", np.zeros(lead) if lead else 0.0)
        # the λ dynamics must be stable for this step, both along the linear pieces and at the
        # equilibrium where the blender sits at its limit (see cogblocks.sync.stability)
        try:
            check_blender(self, self.dt)
        except ValueError as exc:
            raise self._fail(str(exc).removeprefix("Blender: ")) from None

    def saturate(self, x: float, lam: float) -> float:
        """``sat_λ(x)``: hard clip to [−λ, λ], or its smooth version."""
        return alteration(x, lam, self._memoryless)

    def psi_of(self, x: float) -> float:
        """``ψ(x)`` of eq. (5), in [0, 1]."""
        ax = abs(x)
        if ax >= 1.0:
            return 0.0
        if self.psi == "triangular":
            return 1.0 - ax
        return math.exp(1.0 - 1.0 / (1.0 - ax * ax))

    @property
    def init_arguments(self) -> dict[str, Any]:
        """The constructor's arguments, with ``params`` given as its fields: a diagram file holds plain numbers."""
        arguments = dict(super().init_arguments)
        params = arguments.pop("params", None)
        return {**asdict(params), **arguments} if params is not None else arguments

    def lam_inf(self, e: float) -> float:
        """λ∞ of eq. (5) for a deviation ``e = θ_L2 − θ_L0``."""
        return lam_inf(e, self.params)

    def _shift(self, theta_l0: float) -> float:
        """This tick's alteration θ_L2 − θ_L0, from the inputs and the state (output and update agree on it)."""
        theta_ref = float(self.theta_ref.value)
        d = _wrap_pi(theta_ref - theta_l0) if math.isfinite(theta_ref) else 0.0
        if self.params.deliverable_law and not math.isfinite(theta_ref):
            return 0.0
        return alteration(d, self.lam_now, self.params, self.shift_now, self.dt)

    def _shift_rows(self, theta_l0: np.ndarray) -> np.ndarray:
        """:meth:`_shift` of every run of a batch, with the same operations on arrays."""
        theta_ref = self.theta_ref.value
        asked = np.isfinite(theta_ref)
        with np.errstate(invalid="ignore"):
            d = np.where(asked, np.pi - np.mod(np.pi - (theta_ref - theta_l0), TWO_PI), 0.0)
        shift = alteration(d, self.lam_now, self.params, self.shift_now, self.dt)
        return np.where(asked, shift, 0.0) if self.params.deliverable_law else shift

    def _rows(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        """θ_L0, the alteration, θ_L2 of every run and the runs with a finite θ_L0 (None: all of them)."""
        theta_l0 = self.theta_l0.value
        ok = np.isfinite(theta_l0)
        with np.errstate(invalid="ignore"):
            shift = self._shift_rows(theta_l0)
            theta_l2 = np.mod(theta_l0 + shift, TWO_PI)
        theta_l2[theta_l2 >= TWO_PI] = 0.0
        return theta_l0, shift, theta_l2, None if ok.all() else ok

    def _output_rows(self) -> None:
        _, _, theta_l2, ok = self._rows()
        np.copyto(self.theta_l2.value, theta_l2, where=True if ok is None else ok)
        np.copyto(self.lam.value, self.lam_now, where=True if ok is None else ok)

    def _update_rows(self) -> None:
        theta_l0, shift, theta_l2, ok = self._rows()
        with np.errstate(invalid="ignore"):
            lam = lam_step(self.lam_now, np.pi - np.mod(np.pi - (theta_l2 - theta_l0), TWO_PI), self.params, self.dt)
        np.copyto(self.lam_now, lam, where=True if ok is None else ok)
        np.copyto(self.shift_now, shift, where=True if ok is None else ok)

    def output(self, k: int) -> None:
        if self.batch is not None:
            self._output_rows()
            return
        theta_l0 = float(self.theta_l0.value)
        if not math.isfinite(theta_l0):
            return
        theta_l2 = wrap_angle(theta_l0 + self._shift(theta_l0))
        self.theta_l2.value[...] = theta_l2
        self.lam.value[...] = self.lam_now

    def update(self, k: int) -> None:
        if self.batch is not None:
            self._update_rows()
            return
        theta_l0 = float(self.theta_l0.value)
        if not math.isfinite(theta_l0):
            return
        shift = self._shift(theta_l0)
        theta_l2 = wrap_angle(theta_l0 + shift)
        # eq. (6), forward Euler, with e from this tick's θ_L2 and θ_L0
        self.lam_now = lam_step(self.lam_now, _wrap_pi(theta_l2 - theta_l0), self.params, self.dt)
        self.shift_now = shift
