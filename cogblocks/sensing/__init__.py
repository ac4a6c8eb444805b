"""Sensing: Kalman front ends for noisy tracked positions, and the L1 delay-compensating avatar."""

from cogblocks.sensing.kalman import KalmanEstimator, fit_noise
from cogblocks.sensing.l1 import L1, KinematicPredictor

__all__ = ["L1", "KalmanEstimator", "KinematicPredictor", "fit_noise"]
