"""The identification's errors against the true drifting values of a noisy group."""

from __future__ import annotations

import dataclasses

import numpy as np

from cogblocks.analysis.sync_identification import identification_errors
from cogblocks.data.groups import GroupNoise, SyncGroup

GROUP = SyncGroup("ring of 6", 6, 0.9, (2.0, 2.6, 3.1, 3.3, 4.0, 4.4), 2, 40.0)
NOISE = GroupNoise(sigma=(0.2,) * 6, drift_spread=(0.1,) * 6, drift_tau=8.0, seed=4)


def test_noise_free_identification_is_exact_and_reports_no_drift():
    errors = identification_errors(GROUP, duration=10.0)
    assert errors["omega_rms_late"] < 1e-3 and errors["gain_abs_error_late"] < 1e-3
    assert not np.any(errors["omega_drift_rms"])
    np.testing.assert_allclose(errors["t"], np.arange(1, 11) * 1.0)


def test_under_noise_and_drift_forgetting_omega_lowers_both_errors():
    noisy = dataclasses.replace(GROUP, noise=NOISE)
    plain = identification_errors(noisy)
    tracking = identification_errors(noisy, omega_forgetting=0.995)
    assert plain["omega_drift_rms"][-1] > 0.1  # the frequencies did drift
    assert plain["omega_rms_late"] > 0.1  # plain least squares estimates the run's mean, not today's ω
    assert tracking["omega_rms_late"] < 0.8 * plain["omega_rms_late"]
    assert tracking["gain_abs_error_late"] < plain["gain_abs_error_late"]
