"""The networks :class:`~cogblocks.amplification.OptimalBlender` constrains, evaluated as one.

Every member is a one-hidden-layer ReLU network (:class:`~cogblocks.amplification.EncoderNet`) of the 60
profile inputs, or of those and the six kinematic features (``mlp_kinematic``). Their first layers are
stacked with the input normalisation folded in, so all members cost one matrix product; with any
kinematic member the input is the profile followed by the features, and the profile-only members
weigh the features by zero.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from cogblocks.amplification.encoder import N_POINTS, EncoderNet, movement_length, resampling_matrix
from cogblocks.amplification.encoder_casadi import _weights, _weights_key
from cogblocks.amplification.judges import FEATURES, KINEMATIC_INPUTS, kinematic_features
from cogblocks.amplification.plan import sigmoid

__all__ = ["StackedNetworks", "kinematic_member"]


def kinematic_member(network: EncoderNet, owner: str = "OptimalBlender") -> bool:
    """Whether ``network`` takes the kinematic features after the profile (66 inputs) or only the profile (60).

    Raises
    ------
    ValueError
        For any other number of inputs, or a network whose checkpoint says it divides the profile by the
        peak speed (``mlp_shape_kinematic``: not affine in the plan).
    """
    profile, inputs = 3 * N_POINTS, network.hidden.in_features
    architecture = str(getattr(network, "checkpoint", {}).get("architecture", "mlp"))
    if inputs == profile or (inputs == profile + len(FEATURES) and not KINEMATIC_INPUTS.get(architecture, False)):
        return inputs != profile
    raise ValueError(
        f"{owner}: network must take the {profile} profile inputs, or those and the {len(FEATURES)} kinematic "
        f"features (architecture 'mlp_kinematic'); got {inputs} inputs (architecture {architecture!r})"
    )


class StackedNetworks:
    """Several encoder networks as one function of their inputs (see the module docstring).

    Parameters
    ----------
    network : EncoderNet or sequence of EncoderNet
        The members, at least one.
    owner : str
        Named in error messages.

    Attributes
    ----------
    networks : list of EncoderNet
    kinematics : bool
        Whether any member takes the kinematic features (the inputs are then 66, else 60).
    w1, b1 : numpy.ndarray
        The stacked first layers, normalisation folded in: (members·hidden, inputs) and (members·hidden,).
    w2 : list of numpy.ndarray
        Each member's output weights.
    b2 : numpy.ndarray
        The members' output biases.
    key : str
        A digest of the weights (the key of casadi's solver cache).
    """

    def __init__(self, network: EncoderNet | Sequence[EncoderNet], owner: str = "OptimalBlender") -> None:
        networks = [network] if isinstance(network, EncoderNet) else network
        if (
            not isinstance(networks, (list, tuple))
            or not networks
            or not all(isinstance(n, EncoderNet) for n in networks)
        ):
            given = type(network).__name__ if not isinstance(networks, (list, tuple)) else f"{len(networks)} items"
            if isinstance(networks, (list, tuple)) and networks:
                given += " of types " + ", ".join(sorted({type(n).__name__ for n in networks}))
            raise ValueError(f"{owner}: network must be an EncoderNet or a non-empty list of them, got {given}")
        self.networks = list(networks)
        self.kinematics = any([kinematic_member(n, owner) for n in self.networks])
        weights = [_weights(n) for n in self.networks]
        self.key = _weights_key(*weights)
        first = [w["w1"] / w["scale"] for w in weights]
        if self.kinematics:  # the profile-only members weigh the kinematic features by zero
            first = [np.pad(w1, ((0, 0), (0, 3 * N_POINTS + len(FEATURES) - w1.shape[1]))) for w1 in first]
        self.w1 = np.vstack(first)
        self.b1 = np.concatenate([w["b1"] - (w["w1"] / w["scale"]) @ w["mean"] for w in weights])
        self.w2 = [w["w2"] for w in weights]
        self.b2 = np.array([w["b2"] for w in weights])

    def logits(self, x: np.ndarray) -> np.ndarray:
        """Every member's logit at input ``x`` (the profile, followed by the features with kinematic members)."""
        hidden = np.split(np.maximum(self.w1 @ x + self.b1, 0.0), len(self.w2))
        return np.array([w2 @ h for w2, h in zip(self.w2, hidden, strict=True)]) + self.b2

    def inputs(self, movement: np.ndarray, dt: float, rest_speed: float) -> np.ndarray:
        """The input for a movement (L, 3) restricted to its duration: its profile (and kinematic features)."""
        profile = (resampling_matrix(len(movement)) @ movement).T.reshape(-1)
        return np.r_[profile, kinematic_features(movement, dt, rest_speed)] if self.kinematics else profile

    def eps(self, velocity: np.ndarray, dt: float, rest_speed: float) -> np.ndarray:
        """ε̂ of every member for a padded movement (T, 3) restricted to its samples faster than ``rest_speed``.

        NaN for a movement that never moves.
        """
        velocity = np.asarray(velocity, dtype=np.float64)
        length = movement_length(velocity, rest_speed)
        if length == 0:
            return np.full(len(self.networks), math.nan)
        return np.array([sigmoid(float(z)) for z in self.logits(self.inputs(velocity[:length], dt, rest_speed))])
