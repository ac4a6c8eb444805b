"""random_groups with noise: the noise-free draws unchanged, noise parameters in their ranges, splits apart."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cogblocks.data.groups import NOISE_RANGES, GroupNoise, SyncGroup, random_groups


def test_a_noisy_group_is_the_noise_free_group_plus_noise():
    for split in ("train", "validation", "test"):
        plain, noisy = random_groups(12, split, 4), random_groups(12, split, 4, noise=True)
        for a, b in zip(plain, noisy, strict=True):
            assert a.noise is None and b.noise is not None
            assert dataclasses.replace(b, noise=None, name=a.name) == a
            assert b.name == f"{a.name}, noisy"


def test_noise_parameters_are_drawn_in_their_ranges_and_spread_over_them():
    groups = random_groups(200, "validation", 0, noise=True)
    sigma = np.concatenate([g.noise.sigma for g in groups])
    spread = np.concatenate([g.noise.drift_spread for g in groups])
    tau = np.array([g.noise.drift_tau for g in groups])
    for values, name in ((sigma, "sigma"), (spread, "drift_spread"), (tau, "drift_tau")):
        low, high = NOISE_RANGES[name]
        assert low <= values.min() and values.max() <= high
        assert values.min() < low + 0.1 * (high - low) and values.max() > high - 0.1 * (high - low)
    # σ is log-uniform: its median is the geometric mean of the range (±5 % with 2000 draws)
    assert np.median(sigma) == pytest.approx(np.sqrt(np.prod(NOISE_RANGES["sigma"])), rel=0.05)
    assert len({g.noise.seed for g in groups}) == len(groups)


def test_the_splits_draw_other_noise_and_the_draw_does_not_depend_on_n():
    validation, test = random_groups(5, "validation", 0, noise=True), random_groups(5, "test", 0, noise=True)
    assert all(a.noise != b.noise for a, b in zip(validation, test, strict=True))
    assert random_groups(2, "validation", 0, noise=True) == validation[:2]


def test_noise_of_the_wrong_size_is_refused():
    noise = GroupNoise(sigma=(0.1, 0.2), drift_spread=(0.1, 0.1), drift_tau=10.0, seed=0)
    with pytest.raises(ValueError, match="noise for 2 participants, n = 3"):
        SyncGroup(name="g", n=3, gain=1.0, omega=(1.0, 2.0, 3.0), assisted=0, duration=1.0, noise=noise)
    with pytest.raises(ValueError, match="sigma and drift_spread must be >= 0"):
        GroupNoise(sigma=(-0.1,), drift_spread=(0.1,), drift_tau=10.0, seed=0)
    with pytest.raises(ValueError, match="2 sigmas for 1 drift spreads"):
        GroupNoise(sigma=(0.1, 0.1), drift_spread=(0.1,), drift_tau=10.0, seed=0)


def test_plant_options_are_the_noise_for_the_plant():
    group = random_groups(1, "train", 0, noise=True)[0]
    assert group.plant_options() == {
        "noise": group.noise.sigma,
        "drift_spread": group.noise.drift_spread,
        "drift_tau": group.noise.drift_tau,
        "seed": group.noise.seed,
    }
    assert dataclasses.replace(group, noise=None).plant_options() == {}
