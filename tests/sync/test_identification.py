"""KuramotoRLS with a forgetting of its own for the frequencies: the estimate kept, ω's information lowered only."""

from __future__ import annotations

import numpy as np
import pytest

from cogblocks.sync.group import ring_adjacency
from cogblocks.sync.identification import KuramotoRLS, coupling_regressor


def _feed(rls: KuramotoRLS, omega_of_k, gain: float, n_steps: int, dt: float = 0.01) -> None:
    """Exact Euler increments of a ring of 5 whose frequencies are ``omega_of_k(k)`` (no noise)."""
    a = ring_adjacency(5)
    theta = np.array([0.0, 0.4, 1.1, 2.0, 2.6])
    for k in range(n_steps):
        nxt = np.mod(theta + dt * (omega_of_k(k) + gain * coupling_regressor(theta, a)), 2 * np.pi)
        rls.observe(theta, theta, nxt, dt)
        theta = nxt


def test_the_walk_keeps_the_estimate_and_adds_uncertainty_on_omega_only():
    """Constant frequencies, exact increments: the estimate is exact with the walk too; one walk step keeps it and
    raises the covariance of each ω by (1 − ρ_ω)², K's not at all (computed here from the information)."""
    omega = np.array([1.0, 2.0, 2.5, 3.0, 4.0])
    rls = KuramotoRLS(ring_adjacency(5), omega_forgetting=0.99)
    _feed(rls, lambda k: omega, 0.7, 200)
    np.testing.assert_allclose(rls.estimate()[0], omega, atol=1e-4)
    assert rls.estimate()[1] == pytest.approx(0.7, abs=1e-4)
    before, covariance = np.linalg.solve(rls.info, rls.rhs), np.linalg.inv(rls.info)
    rls._walk_omega()
    np.testing.assert_allclose(np.linalg.solve(rls.info, rls.rhs), before, atol=1e-9)
    grown = np.linalg.inv(rls.info) - covariance
    np.testing.assert_allclose(grown, np.diag(np.r_[np.full(5, 1e-4), 0.0]), atol=1e-9)


def test_a_drifting_frequency_is_tracked_with_omega_forgetting_and_k_is_kept():
    """ω_0 ramps at 0.05 rad/s² over 20 s: plain least squares estimates about the run's mean (0.5 rad/s behind);
    with a memory of 1 s (ρ_ω = 0.99) the lag is about slope × memory = 0.05 rad/s, and K is kept."""
    omega = np.array([1.0, 2.0, 2.5, 3.0, 4.0])

    def ramp(k: int) -> np.ndarray:
        return omega + np.r_[k * 0.01 / 20.0, 0, 0, 0, 0]

    plain, tracking = KuramotoRLS(ring_adjacency(5)), KuramotoRLS(ring_adjacency(5), omega_forgetting=0.99)
    for rls in (plain, tracking):
        _feed(rls, ramp, 0.7, 2000)
    true_now = ramp(1999)
    assert abs(plain.estimate()[0][0] - true_now[0]) > 0.3
    assert abs(tracking.estimate()[0][0] - true_now[0]) < 0.07
    assert tracking.estimate()[1] == pytest.approx(0.7, abs=0.02)


def test_omega_forgetting_outside_its_range_is_refused():
    for bad in (0.0, 1.0, 1.5):
        with pytest.raises(ValueError, match=r"omega_forgetting must be in \(0, 1\) or None"):
            KuramotoRLS(ring_adjacency(3), omega_forgetting=bad)
