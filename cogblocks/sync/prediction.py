"""The group, blender and reference as a smooth casadi ODE: what the MPC optimises through.

State ``x = (θ_1 … θ_N, λ, θ_ref)`` (unwrapped phases), control ``u`` = the reference's frequency, parameters
``(ω, K)``. The blender is eqs. (3)–(6) made differentiable: the smooth saturation
``d / (1 + (d/λ)^p)^(1/p)`` (p even) instead of the clip, a softened ``|e|`` and ``max(0, ·)`` in ψ, and
the switch between κ⁺ and κ⁻ written as ``κ⁺ (λ − λ∞) + (κ⁻ − κ⁺) softplus(λ − λ∞)``. The phase
difference θ_ref − θ_L0 is wrapped with ``atan2(sin, cos)``, smooth away from ±π. The order parameter is
that of the phases the group sees (θ_L2 substituted), as the deliverable measures it.
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from cogblocks.sync.blending import BlenderParams, lam_rate

__all__ = ["SMOOTHING", "rk4_step", "seen_order", "sync_ode"]

#: Width (rad) of the smoothing of |e|, max(0, ·) and the κ switch.
SMOOTHING = 1e-3


def _blend(x: Any, n: int, assisted: int, blender: BlenderParams, p: int) -> tuple[Any, Any]:
    """θ̃ (the phases the group sees) and the alteration ``θ_L2 − θ_L0`` of state ``x``."""
    theta, lam, theta_ref = x[:n], x[n], x[n + 1]
    diff = theta_ref - theta[assisted]
    d = ca.atan2(ca.sin(diff), ca.cos(diff))
    ratio = d / lam
    # constpow, not pow: pow's derivative carries log(base), NaN at d = 0
    shift = d / ca.constpow(1.0 + ca.constpow(ratio * ratio, p // 2), 1.0 / p)
    seen = ca.vertcat(theta[:assisted], theta[assisted] + shift, theta[assisted + 1 :])
    return seen, shift


def seen_order(x: Any, n: int, assisted: int, blender: BlenderParams, p: int) -> Any:
    """The order parameter of the phases the group sees at state ``x`` (smoothed at r = 0)."""
    seen, _ = _blend(x, n, assisted, blender, p)
    c, s = ca.sum1(ca.cos(seen)) / n, ca.sum1(ca.sin(seen)) / n
    return ca.sqrt(c * c + s * s + 1e-12)


def sync_ode(adjacency: np.ndarray, assisted: int, blender: BlenderParams, p: int = 4) -> ca.Function:
    """``f(x, u, omega, gain) -> dx/dt`` of the group with its blender and a reference of frequency ``u``."""
    n = adjacency.shape[0]
    x, u = ca.SX.sym("x", n + 2), ca.SX.sym("u")
    omega, gain = ca.SX.sym("omega", n), ca.SX.sym("gain")
    seen, shift = _blend(x, n, assisted, blender, p)
    sin_s, cos_s = ca.sin(seen), ca.cos(seen)
    a = ca.sparsify(ca.DM(adjacency))  # a ring's zeros cost nothing
    # Σ_j a_ij sin(s_j − s_i) = cos s_i (A sin s)_i − sin s_i (A cos s)_i
    pull = cos_s * ca.mtimes(a, sin_s) - sin_s * ca.mtimes(a, cos_s)
    dlam = lam_rate(x[n], shift, blender, SMOOTHING)
    dx = ca.vertcat(omega + gain * pull, dlam, u)
    return ca.Function("sync_ode", [x, u, omega, gain], [dx], ["x", "u", "omega", "gain"], ["dx"])


def rk4_step(ode: ca.Function, x: Any, u: Any, omega: Any, gain: Any, h: float) -> Any:
    """One classical Runge–Kutta step of length ``h``."""
    k1 = ode(x, u, omega, gain)
    k2 = ode(x + 0.5 * h * k1, u, omega, gain)
    k3 = ode(x + 0.5 * h * k2, u, omega, gain)
    k4 = ode(x + h * k3, u, omega, gain)
    return x + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
