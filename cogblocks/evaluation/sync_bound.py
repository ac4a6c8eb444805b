"""How high can the L2 architecture push the order parameter? A per-group yardstick for every motion computer.

:func:`upper_bound` is the best time-averaged r found within the blender's limits: the larger of the whole-run
optimal control of :func:`~cogblocks.analysis.sync_ocp.windowed_control_bound` (exact discrete model, IPOPT,
started from doing nothing, the circular mean and the best constant frequency) and of
:func:`constant_frequency_scan` (the coarse grid of constant reference frequencies the held-out evaluation
first used). :func:`constant_frequency_bound` is the best of a dense grid of constant reference frequencies.
Values are re-simulated through the real blocks (:func:`~cogblocks.analysis.sync_ocp.resimulate`), except the
scan's, which runs the same equations on NumPy. All are values reached by an actual reference: the best known,
not a proof (the problem is not convex), so a policy above them is a finding, not a contradiction.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from cogblocks.analysis.sync_ocp import THOROUGH, resimulate, windowed_control_bound
from cogblocks.data.groups import SyncGroup
from cogblocks.sync.blending import BlenderParams, lam_step
from cogblocks.sync.blending import alteration as blended
from cogblocks.sync.model import DT, SyncModel, order_parameter

__all__ = ["constant_frequency_bound", "constant_frequency_scan", "resimulate", "upper_bound"]


def _setup(group: SyncGroup, adjacency: Any, duration: float | None, blender: BlenderParams | None) -> tuple:
    a = group.adjacency() if adjacency is None else np.asarray(adjacency, dtype=float)
    if a.shape != (group.n, group.n):
        raise ValueError(f"adjacency must be {group.n}x{group.n}, got shape {a.shape}")
    duration = group.duration if duration is None else float(duration)
    return a, round(duration / DT) + 1, blender or BlenderParams()


def _constant_grid(group: SyncGroup, a: np.ndarray, n_steps: int, params: BlenderParams, grid: np.ndarray):
    """Mean r of every constant frequency in ``grid`` on the batched NumPy model (the blocks' equations)."""
    model = SyncModel(
        omega=np.tile(np.asarray(group.omega, dtype=float), (len(grid), 1)),
        gain=np.full(len(grid), group.gain),
        adjacency=a,
        assisted=group.assisted,
        blender=params,
    )
    theta = np.zeros((len(grid), group.n))
    lam = np.full(len(grid), params.lam_max)
    total, shift = np.zeros(len(grid)), np.zeros(len(grid))
    for k in range(n_steps):
        seen, shift, lam = model.blend(theta, np.mod(grid * k * DT, 2 * np.pi), lam, shift)
        total += order_parameter(seen)
        theta, _ = model.advance(theta, seen, np.zeros(len(grid)), grid)
    return total / n_steps


def constant_frequency_bound(
    group: SyncGroup,
    *,
    adjacency: Any = None,
    duration: float | None = None,
    blender: BlenderParams | None = None,
    frequencies: np.ndarray | None = None,
) -> float:
    """Best time-averaged r over a grid of constant reference frequencies, θ_ref(t) = ω t.

    ``frequencies`` defaults to −15 … 15 rad/s by 0.05. The grid is scanned on the batched model; the
    best frequency is re-simulated through the blocks (:func:`resimulate`) for the value returned.
    """
    a, n_steps, params = _setup(group, adjacency, duration, blender)
    grid = np.arange(-15.0, 15.0 + 1e-9, 0.05) if frequencies is None else np.asarray(frequencies, dtype=float)
    best = grid[int(np.argmax(_constant_grid(group, a, n_steps, params, grid)))]
    return resimulate(group, best * DT * np.arange(n_steps), adjacency=a, blender=params)


def upper_bound(
    group: SyncGroup,
    *,
    adjacency: Any = None,
    duration: float | None = None,
    blender: BlenderParams | None = None,
    max_iter: int = 20,
    pace: bool = True,
    thorough: bool = False,
) -> float:
    """The best r found: the larger of :func:`~cogblocks.analysis.sync_ocp.windowed_control_bound` (whole-run
    optimal control of the alteration, IPOPT with ``max_iter`` iterations per window, started from the
    ``pace`` policy's reference too if ``pace``) and, on the group's own graph, :func:`constant_frequency_scan`.
    ``thorough`` searches harder (:data:`~cogblocks.analysis.sync_ocp.THOROUGH`: the ``pace`` and the default
    policy's closed-loop references as starts, three more sweeps; about 3× the CPU), ``pace`` then being moot.

    Each is an r that some reference reaches, so the larger is the tighter; neither is a proof that no
    reference does better. On a noisy group it is the clairvoyant bound (the noise draw known; see
    :mod:`~cogblocks.analysis.sync_ocp`) and the noise-free scan is left out.
    """
    kw = {"adjacency": adjacency, "duration": duration, "blender": blender}
    search = THOROUGH if thorough else {"pace": pace}
    best = windowed_control_bound(group, max_iter=max_iter, **search, **kw)
    if adjacency is None and group.noise is None:  # the scan simulates the group's own graph, noise-free
        scanned = group if duration is None else dataclasses.replace(group, duration=float(duration))
        best = max(best, constant_frequency_scan(scanned, blender))
    return best


def constant_frequency_scan(
    group: SyncGroup,
    blender_params: BlenderParams | None = None,
    *,
    n_frequencies: int = 41,
    n_phases: int = 4,
    margin: float = 0.5,
    dt: float = DT,
) -> float:
    """Best mean order parameter over constant-frequency references, all simulated at once (fast, coarse).

    The cheap bound of the held-out evaluation (:mod:`cogblocks.evaluation.sync_heldout`): a coarse grid
    around the natural frequencies, simulated on the batched model without re-simulation through the
    blocks. :func:`upper_bound` is tighter and much slower.

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
        raise ValueError("constant_frequency_scan: n_frequencies and n_phases must be at least 1")
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
    lam = np.full(len(omega_c), params.lam_max)
    r_sum = np.zeros(len(omega_c))
    alteration = np.zeros(len(omega_c))
    for k in range(n_steps + 1):
        theta_l0 = theta[:, a]
        d = np.mod(phase0 + omega_c * (k * dt) - theta_l0 + np.pi, 2.0 * np.pi) - np.pi
        alteration = blended(d, lam, params, alteration, dt)
        lam = lam_step(lam, alteration, params, dt)
        theta_tilde = theta.copy()
        theta_tilde[:, a] = theta_l0 + alteration
        z = np.exp(1j * theta_tilde)
        r_sum += np.abs(z.sum(axis=1))
        theta += dt * (model.omega + model.gain * (z.conj() * (model.adjacency @ z.T).T).imag)
    return float(r_sum.max() / (n * (n_steps + 1)))
