"""How high the L2 architecture could lift a group's mean order parameter: bounds to compare policies with.

:func:`constant_frequency_bound` is the best mean r over a grid of open-loop references
``θ_ref(t) = θ_ref0 + ω_c t`` sent through the real blender (eqs. (3)-(6)), on the group's model
(:class:`~cogblocks.sync.model.SyncModel`, the same Euler steps as the diagram). It is the optimum
of a restricted class of references, so a closed-loop policy may exceed it. :func:`upper_bound` is
the bound the held-out evaluation divides by.
"""

from __future__ import annotations

import numpy as np

from cogblocks.data.groups import SyncGroup
from cogblocks.sync.model import DT, BlenderParams, SyncModel

__all__ = ["constant_frequency_bound", "upper_bound"]


def constant_frequency_bound(
    group: SyncGroup,
    blender_params: BlenderParams | None = None,
    *,
    n_frequencies: int = 41,
    n_phases: int = 4,
    margin: float = 0.5,
    dt: float = DT,
) -> float:
    """Best mean order parameter over constant-frequency references, all simulated at once.

    Parameters
    ----------
    group : SyncGroup
        Group, graph, assisted participant and duration; the mean is over ticks ``0 … T/dt``.
    blender_params : BlenderParams, optional
        The deliverable's blender by default.
    n_frequencies : int
        Frequencies ω_c, evenly spaced over ``[min ω − margin, max ω + margin]``.
    n_phases : int
        Initial reference phases θ_ref0, evenly spaced over ``[0, 2π)``.
    margin : float
        Extension of the frequency grid beyond the natural frequencies, rad/s.
    dt : float
        Euler step, s.
    """
    if n_frequencies < 1 or n_phases < 1:
        raise ValueError("constant_frequency_bound: n_frequencies and n_phases must be at least 1")
    omega = np.asarray(group.omega, dtype=float)
    frequencies = np.linspace(omega.min() - margin, omega.max() + margin, n_frequencies)
    phases = np.arange(n_phases) * (2.0 * np.pi / n_phases)
    omega_c, phase0 = (x.ravel() for x in np.meshgrid(frequencies, phases))
    model = SyncModel.from_group(group, blender=blender_params, dt=dt)
    params, a, n = model.blender, model.assisted, group.n
    # One lean Euler loop on complex phasors (a few NumPy calls per tick: this loop is the cost of the bound).
    # Same equations as SyncModel.blend/advance; the wraps are dropped where sin/cos make them moot.
    n_steps = round(group.duration / dt)
    theta = np.zeros((len(omega_c), n))
    lam = np.full(len(omega_c), params.lambda_max)
    r_sum = np.zeros(len(omega_c))
    slope = (params.lambda_max - params.lambda_min) / params.e_max
    for k in range(n_steps + 1):
        theta_l0 = theta[:, a]
        alteration = np.clip(np.mod(phase0 + omega_c * (k * dt) - theta_l0 + np.pi, 2.0 * np.pi) - np.pi, -lam, lam)
        lam_inf = np.maximum(params.lambda_min, params.lambda_max - slope * np.abs(alteration))
        lam = lam - dt * np.where(lam <= lam_inf, params.kappa_up, params.kappa_down) * (lam - lam_inf)
        theta_tilde = theta.copy()
        theta_tilde[:, a] = theta_l0 + alteration
        z = np.exp(1j * theta_tilde)
        r_sum += np.abs(z.sum(axis=1))
        theta += dt * (model.omega + model.gain * (z.conj() * (model.adjacency @ z.T).T).imag)
    return float(r_sum.max() / (n * (n_steps + 1)))


def upper_bound(group: SyncGroup, blender_params: BlenderParams | None = None) -> float:
    """Mean order parameter known to be reachable with the blender: here :func:`constant_frequency_bound`."""
    return constant_frequency_bound(group, blender_params)
