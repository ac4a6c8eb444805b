"""The 3D phase chain and the phase3d command."""

import json

import numpy as np

from cogblocks.cli import main
from cogblocks.data.motion3d import generate_motion3d
from cogblocks.diagrams.phase3d import phase_chain, run_phase_chain
from cogblocks.sim import Simulator


def test_phase_chain_links_estimate_l2_and_avatar():
    motion = generate_motion3d(1, duration=12.0)
    d = phase_chain(motion)
    probes = {"valid": "estimator.valid", "l0": "l2.theta_l0", "est": "estimator.theta", "l2": "l2.theta_l2"}
    trace = Simulator(d, probes=probes).run(n_steps=len(motion.t))
    valid = trace["valid"]
    assert not valid[0] and valid[-1]
    np.testing.assert_array_equal(trace["l0"], trace["est"])  # θ_L0 is the estimate
    # the avatar sits on the reference at index round(N θ_L2 / 2π)
    n = len(motion.reference)
    idx = np.floor(n * trace["l2"] / (2 * np.pi) + 0.5).astype(int) % n
    np.testing.assert_allclose(trace["avatar_p"], motion.reference[idx])
    assert np.all(np.isfinite(trace["r"])) and np.all(trace["r"] <= 1.0 + 1e-12)


def test_run_phase_chain_report():
    result = run_phase_chain(seed=2, duration=12.0)
    assert 0.0 < result["r_mean"] <= 1.0
    assert 0.0 < result["valid_from_s"] < 6.0
    assert result["max_dev_rad"] <= np.pi / 2 + 1e-9  # bounded by λ_max
    assert result["avatar_path_mm"] > 0


def test_cli_phase3d_json(capsys):
    assert main(["run", "phase3d", "--trajectories", "2", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert {"mean_error_rad", "p95_error_rad", "mean_error_vs_offline_rad", "n_trajectories"} <= set(result)
    assert result["n_trajectories"] == 2
    assert 0 < result["mean_error_rad"] < result["p95_error_rad"] < 0.5
