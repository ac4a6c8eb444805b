"""Sensing: Kalman front ends for noisy tracked positions, a rest gate, and the L1 delay-compensating avatar."""

from cogblocks.sensing.kalman import KalmanEstimator, fit_noise
from cogblocks.sensing.l1 import L1, KinematicPredictor
from cogblocks.sensing.rest import RestGate, rest_cutoff, rest_speed_bound

__all__ = ["L1", "KalmanEstimator", "KinematicPredictor", "RestGate", "fit_noise", "rest_cutoff", "rest_speed_bound"]
