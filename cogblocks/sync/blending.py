"""The blender's parameters and its law (eqs. 3–6), written once for floats, NumPy arrays and casadi expressions.

The :class:`~cogblocks.sync.blender.Blender` block, its stability check, the NumPy group model, the casadi
predictions and the planners' searches all take one :class:`BlenderParams` and compute the alteration and the λ
dynamics with the functions here, so that a blender swapped in a diagram is the blender every model plans
through. Each function picks its operations from the type of its argument (``abs``/``max`` on floats,
``np.abs``/``np.maximum``/``np.where`` on arrays, ``fabs``/``fmax``/``if_else`` on casadi symbols), and keeps
the order of the floating-point operations of the deliverable's formulas, so every path gives the same bits.

Two blending laws:

* the deliverable's (``continuous=False``, no ``slew``): ``a = sat_λ(wrap_π(θ_ref − θ_L0))``. When the wrapped
  difference crosses ±π the alteration flips from +λ to −λ in one tick;
* the continuous one (``continuous=True``, a ``slew`` in rad/s): the difference is unwrapped around the last
  alteration (``d = a_prev + wrap_π(θ_ref − θ_L0 − a_prev)``), so the alteration keeps its side until the
  difference comes back inside, and it moves by at most ``slew · dt`` per tick, then stays within ±λ.
"""

from __future__ import annotations

import math
import sys
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = [
    "BLENDERS",
    "CONTINUOUS",
    "DELIVERABLE",
    "SLEW",
    "BlenderParams",
    "alteration",
    "blender_params",
    "lam_inf",
    "lam_rate",
    "lam_step",
]

#: Default slew limit (rad/s) of the continuous blender: a change of the alteration below the 0.05 rad per
#: 10 ms tick at which the avatar runs 5 rad/s off the person's pace (docs/explanation/avatar-naturalness.md).
SLEW = 4.5

_OLD_NAMES = {"lambda_min": "lam_min", "lambda_max": "lam_max", "kappa_up": "kappa_plus", "kappa_down": "kappa_minus"}
_SMOOTH_P = 4.0


@dataclass(frozen=True, init=False)
class BlenderParams:
    """Parameters of the L2 blender, eqs. (3)–(6); the defaults are the deliverable's (section 5.2.3.2).

    Attributes
    ----------
    lam_min, lam_max : float
        Range of the threshold λ (rad), ``0 < lam_min <= lam_max``; λ starts at ``lam_max``.
    e_max : float
        Alteration (rad) at which λ's target λ∞ drops to ``lam_min`` (> 0).
    kappa_plus, kappa_minus : float
        Rates (1/s) of eq. (6) while λ rises toward λ∞ (``kappa_plus``, κ⁺) and falls toward it
        (``kappa_minus``, κ⁻); the deliverable picks κ⁻ > κ⁺ so large alterations are cut back fast.
    saturation : {"hard", "smooth"}
        ``sat_λ`` of eq. (4), or the differentiable ``x / (1 + |x/λ|^4)^(1/4)``.
    psi : {"triangular", "bump"}
        ``ψ(x) = max(0, 1 − |x|)`` or ``exp(1 − 1/(1 − x²))`` for ``|x| < 1``.
    continuous : bool
        Unwrap θ_ref − θ_L0 around the last alteration instead of wrapping it to (−π, π]: no sign flip at ±π.
    slew : float or None
        Largest rate of change of the alteration (rad/s); ``None``: unlimited.

    Notes
    -----
    The old spellings ``lambda_min``, ``lambda_max``, ``kappa_up``, ``kappa_down`` are accepted as keywords and
    attributes, with a :class:`DeprecationWarning` naming the new one.
    """

    lam_min: float = 0.3 * math.pi / 2
    lam_max: float = math.pi / 2
    e_max: float = 0.3 * math.pi / 2
    kappa_plus: float = 1.0
    kappa_minus: float = 2.5
    saturation: str = "hard"
    psi: str = "triangular"
    continuous: bool = False
    slew: float | None = field(default=None)

    def __init__(self, **values: Any) -> None:
        for old, new in _OLD_NAMES.items():
            if old in values:
                warnings.warn(f"BlenderParams: {old} is now {new}", DeprecationWarning, stacklevel=2)
                if new in values:
                    raise ValueError(f"BlenderParams: give {new} or its old name {old}, not both")
                values[new] = values.pop(old)
        known = {name for name in self.__dataclass_fields__}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"BlenderParams: unknown parameter(s) {unknown}; known: {sorted(known)}")
        for name, spec in self.__dataclass_fields__.items():
            object.__setattr__(self, name, values.get(name, spec.default))
        self._check()

    def _check(self) -> None:
        for name in ("lam_min", "e_max", "kappa_plus", "kappa_minus"):
            value = getattr(self, name)
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, float))
                or not (value > 0 and math.isfinite(value))
            ):
                raise ValueError(f"BlenderParams: {name} must be a finite number > 0, got {value!r}")
        if isinstance(self.lam_max, bool) or not isinstance(self.lam_max, (int, float)):
            raise ValueError(f"BlenderParams: lam_max must be a number, got {self.lam_max!r}")
        if not (math.isfinite(self.lam_max) and self.lam_max >= self.lam_min):
            raise ValueError(
                f"BlenderParams: lam_max must be finite and >= lam_min = {self.lam_min}, got {self.lam_max}"
            )
        if self.saturation not in ("hard", "smooth"):
            raise ValueError(f"BlenderParams: saturation must be 'hard' or 'smooth', got {self.saturation!r}")
        if self.psi not in ("triangular", "bump"):
            raise ValueError(f"BlenderParams: psi must be 'triangular' or 'bump', got {self.psi!r}")
        if not isinstance(self.continuous, (bool, np.bool_)):
            raise ValueError(f"BlenderParams: continuous must be True or False, got {self.continuous!r}")
        slew = self.slew
        if slew is not None and (
            isinstance(slew, bool) or not isinstance(slew, (int, float)) or not (slew > 0 and math.isfinite(slew))
        ):
            raise ValueError(f"BlenderParams: slew must be None or a finite rate > 0 (rad/s), got {slew!r}")

    def __getattr__(self, name: str) -> Any:
        if name in _OLD_NAMES:
            warnings.warn(f"BlenderParams: {name} is now {_OLD_NAMES[name]}", DeprecationWarning, stacklevel=2)
            return getattr(self, _OLD_NAMES[name])
        raise AttributeError(f"'BlenderParams' object has no attribute {name!r}")

    def lam_inf(self, e: float) -> float:
        """λ∞ of eq. (5) for a deviation ``e = θ_L2 − θ_L0`` (what the stability check reads)."""
        return lam_inf(e, self)

    @property
    def deliverable_law(self) -> bool:
        """Whether the alteration is the deliverable's memoryless ``sat_λ(wrap_π(θ_ref − θ_L0))``."""
        return not self.continuous and self.slew is None


#: The deliverable's blender (section 5.2.3.2).
DELIVERABLE = BlenderParams()
#: The blender whose output never jumps: unwrapped difference, alteration changing by at most :data:`SLEW` rad/s.
CONTINUOUS = BlenderParams(continuous=True, slew=SLEW)
#: The blenders by name, as ``pop_sync(blender=...)``, the live diagrams and ``--blender`` take them.
BLENDERS = {"deliverable": DELIVERABLE, "continuous": CONTINUOUS}


def blender_params(where: str, blender: Any) -> BlenderParams:
    """``blender`` (a name of :data:`BLENDERS`, a :class:`BlenderParams`, a Blender block or ``None``: the
    deliverable's) as a :class:`BlenderParams`; ``where`` names the caller in the error."""
    if blender is None:
        return DELIVERABLE
    if isinstance(blender, str):
        if blender not in BLENDERS:
            raise ValueError(f"{where}: blender must be one of {sorted(BLENDERS)}, got {blender!r}")
        return BLENDERS[blender]
    if isinstance(blender, BlenderParams):
        return blender
    params = getattr(blender, "params", None)
    if isinstance(params, BlenderParams):
        return params
    raise ValueError(
        f"{where}: blender must be a BlenderParams, a Blender or one of {sorted(BLENDERS)}, "
        f"got {type(blender).__name__}"
    )


def _casadi(x: Any) -> Any:
    """The casadi module if ``x`` is a casadi symbol or matrix, else ``None`` (casadi is never imported here)."""
    ca = sys.modules.get("casadi")
    return ca if ca is not None and isinstance(x, (ca.SX, ca.MX, ca.DM)) else None


def _soft_plus(x: Any, width: float, sqrt: Any) -> Any:
    return 0.5 * (x + sqrt(x * x + width * width))


def lam_inf(e: Any, params: BlenderParams, smoothing: float | None = None) -> Any:
    """λ∞ of eq. (5), ``ψ(e / e_max)(λ_max − λ_min) + λ_min``, for a float, an array or a casadi expression ``e``.

    ``smoothing`` (rad, casadi only) softens ``|e|`` and ``max(0, ·)`` of the triangular ψ into
    ``sqrt(e² + w²)`` and a soft plus of width ``w``, for gradient-based solvers.
    """
    span = params.lam_max - params.lam_min
    ca = _casadi(e)
    if ca is not None:
        if smoothing is not None:
            psi = _soft_plus(1.0 - ca.sqrt(e * e + smoothing**2) / params.e_max, smoothing, ca.sqrt)
        elif params.psi == "triangular":
            psi = ca.fmax(0.0, 1.0 - ca.fabs(e) / params.e_max)
        else:
            x = ca.fmin(ca.fabs(e) / params.e_max, 1.0 - 1e-12)
            psi = ca.if_else(ca.fabs(e) < params.e_max, ca.exp(1.0 - 1.0 / (1.0 - x * x)), 0.0)
        return params.lam_min + span * psi
    if isinstance(e, np.ndarray):
        ax = np.abs(e / params.e_max)
        if params.psi == "triangular":
            psi = np.maximum(0.0, 1.0 - ax)
        else:
            with np.errstate(divide="ignore", over="ignore"):
                psi = np.where(ax < 1.0, np.exp(1.0 - 1.0 / (1.0 - np.minimum(ax, 1.0) ** 2)), 0.0)
        return psi * span + params.lam_min
    ax = abs(e / params.e_max)
    if ax >= 1.0:
        psi = 0.0
    elif params.psi == "triangular":
        psi = 1.0 - ax
    else:
        psi = math.exp(1.0 - 1.0 / (1.0 - ax * ax))
    return psi * span + params.lam_min


def lam_step(lam: Any, e: Any, params: BlenderParams, dt: float) -> Any:
    """Eq. (6) by forward Euler: λ of the next tick from λ and this tick's alteration ``e`` (κ⁺ while
    ``λ <= λ∞``, else κ⁻); floats, arrays or casadi expressions."""
    target = lam_inf(e, params)
    ca = _casadi(lam) or _casadi(e)
    if ca is not None:
        kappa = ca.if_else(lam <= target, params.kappa_plus, params.kappa_minus)
    elif isinstance(lam, np.ndarray) or isinstance(e, np.ndarray):
        kappa = np.where(lam <= target, params.kappa_plus, params.kappa_minus)
    else:
        kappa = params.kappa_plus if lam <= target else params.kappa_minus
    return lam - dt * kappa * (lam - target)


def lam_rate(lam: Any, e: Any, params: BlenderParams, smoothing: float) -> Any:
    """Eq. (6) in continuous time, smoothed for gradient-based solvers (casadi): ``dλ/dt = −κ (λ − λ∞)`` with the
    switch between κ⁺ and κ⁻ written ``κ⁺ g + (κ⁻ − κ⁺) softplus(g)``, ``g = λ − λ∞(e)`` (see :func:`lam_inf`)."""
    ca = _casadi(lam) or _casadi(e)
    gap = lam - lam_inf(e, params, smoothing)
    sqrt = ca.sqrt if ca is not None else np.sqrt
    return -(params.kappa_plus * gap + (params.kappa_minus - params.kappa_plus) * _soft_plus(gap, smoothing, sqrt))


def _wrap(x: Any, ca: Any) -> Any:
    if ca is not None:
        return ca.atan2(ca.sin(x), ca.cos(x))
    if isinstance(x, np.ndarray):
        return np.pi - np.mod(np.pi - x, 2.0 * np.pi)
    return math.pi - (math.pi - x) % (2.0 * math.pi)


def _clip(x: Any, low: Any, high: Any, ca: Any) -> Any:
    if ca is not None:
        return ca.fmin(ca.fmax(x, low), high)
    if isinstance(x, np.ndarray) or isinstance(low, np.ndarray) or isinstance(high, np.ndarray):
        return np.minimum(np.maximum(x, low), high)
    return high if x > high else (low if x < low else x)


def alteration(d: Any, lam: Any, params: BlenderParams, previous: Any = None, dt: float = 0.0) -> Any:
    """Eqs. (3)–(4): the alteration ``θ_L2 − θ_L0`` of a tick from the wrapped difference ``d = wrap_π(θ_ref − θ_L0)``.

    With the deliverable's law this is ``sat_λ(d)``. With ``params.continuous`` the difference is first unwrapped
    around the last tick's alteration ``previous``; with ``params.slew`` the result moves at most ``slew · dt`` from
    ``previous`` and is then kept within ±λ. ``previous=None`` (not known) applies neither. Floats, arrays or casadi
    expressions.
    """
    ca = _casadi(d) or _casadi(lam) or _casadi(previous)
    if params.continuous and previous is not None:
        d = previous + _wrap(d - previous, ca)
    if params.saturation == "hard":
        a = _clip(d, -lam, lam, ca)
    else:
        ratio = d / lam
        if ca is not None:
            a = d / ca.constpow(1.0 + ca.constpow(ratio * ratio, 2), 0.25)
        else:
            a = d / (1.0 + abs(ratio) ** _SMOOTH_P) ** (1.0 / _SMOOTH_P)
    if params.slew is None or previous is None:
        return a
    step = params.slew * dt
    return _clip(_clip(a, previous - step, previous + step, ca), -lam, lam, ca)
