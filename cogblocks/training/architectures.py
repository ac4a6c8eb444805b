"""Candidate encoder architectures and inputs for the ensembles, compared by the recipe's cross-validation.

Every candidate maps one row of an input matrix (n, inputs) to ε̂ and has ``predict`` like
:class:`~cogblocks.amplification.EncoderNet`, so :mod:`cogblocks.training.recipe` trains and scores
them alike:

- ``"mlp"``: :class:`~cogblocks.amplification.EncoderNet` on the 60 resampled velocity points;
- ``"cnn"``: :class:`ConvEncoder`, one 1D convolution over the resampled velocity profile (3 channels,
  20 points), ReLU, a linear read-out. Convolution is linear, so the trained network *is* an
  :class:`EncoderNet` with ``channels × 20`` hidden units whose first layer is the convolution's
  (banded) matrix (:meth:`ConvEncoder.to_encoder_net`): the blender's casadi and linearised
  solvers can constrain it unchanged;
- ``"gru"``: :class:`GRUEncoder`, a GRU over the 20 points (3 values each), its last state read out
  linearly; a judge only (the linearised solver needs a piecewise linear network);
- ``"mlp_kinematic"``: EncoderNet on the 60 points and the six
  :func:`~cogblocks.amplification.judges.kinematic_features` (66 inputs): duration and peak speed are
  not in the resampled profile; a judge, and a member the linearised solver constrains
  (:mod:`cogblocks.amplification.kinematics`);
- ``"mlp_shape_kinematic"``: EncoderNet on the profile divided by the movement's peak speed (shape
  only) and the six kinematic features; a judge only.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from cogblocks.amplification.encoder import N_POINTS, EncoderNet, StandardisedNet
from cogblocks.amplification.judges import KINEMATIC_INPUTS, ensemble_inputs

__all__ = ["ARCHITECTURES", "ConvEncoder", "GRUEncoder", "architecture_inputs", "as_encoder_net", "build_network"]

#: Architecture names understood by :func:`build_network` and :func:`architecture_inputs`.
ARCHITECTURES = ("mlp", "cnn", "gru", "mlp_kinematic", "mlp_shape_kinematic")

_AXES = 3


class _Standardised(StandardisedNet):
    """A standardised network that reads its inputs as a velocity profile."""

    def profile(self, x: torch.Tensor) -> torch.Tensor:
        """Standardised inputs as a (batch, 3 axes, 20 points) profile."""
        return ((x - self.mean) / self.scale).reshape(-1, _AXES, N_POINTS)


class ConvEncoder(_Standardised):
    """ε̂ = sigmoid(w · relu(conv(x)) + b): one 1D convolution over the resampled velocity profile.

    Parameters
    ----------
    channels : int
        Convolution filters (hidden units per point).
    kernel : int
        Odd kernel width in points; zero padding keeps the 20 points.
    dropout : float
        Dropout on the hidden units during training.
    """

    def __init__(self, channels: int = 16, kernel: int = 5, dropout: float = 0.2) -> None:
        super().__init__(_AXES * N_POINTS)
        if kernel % 2 != 1:
            raise ValueError(f"ConvEncoder: kernel must be odd, got {kernel}")
        self.conv = nn.Conv1d(_AXES, channels, kernel, padding=kernel // 2)
        self.dropout = nn.Dropout(dropout)
        self.out = nn.Linear(channels * N_POINTS, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """ε̂ of inputs of shape (batch, 60), shape (batch,)."""
        hidden = torch.relu(self.conv(self.profile(x))).flatten(1)
        return torch.sigmoid(self.out(self.dropout(hidden))).squeeze(-1)

    def to_encoder_net(self) -> EncoderNet:
        """The same function as an :class:`EncoderNet` (hidden unit ``c·20 + t``: filter ``c`` at point ``t``)."""
        n_in = _AXES * N_POINTS
        with torch.no_grad():
            weight = self.conv.weight.double()
            basis = torch.eye(n_in, dtype=torch.float64).reshape(n_in, _AXES, N_POINTS)
            columns = nn.functional.conv1d(basis, weight, padding=self.conv.padding[0]).flatten(1)
            network = EncoderNet(n_inputs=n_in, hidden=columns.shape[1], dropout=self.dropout.p)
            network.mean.copy_(self.mean)
            network.scale.copy_(self.scale)
            network.hidden.weight.copy_(columns.T.float())
            network.hidden.bias.copy_(self.conv.bias.repeat_interleave(N_POINTS))
            network.out.weight.copy_(self.out.weight)
            network.out.bias.copy_(self.out.bias)
        network.eval()
        return network


class GRUEncoder(_Standardised):
    """ε̂ = sigmoid(w · h₂₀ + b), h₂₀ the last state of a GRU run over the 20 points (3 values each).

    Parameters
    ----------
    hidden : int
        GRU state size.
    dropout : float
        Dropout on the last state during training.
    """

    def __init__(self, hidden: int = 32, dropout: float = 0.2) -> None:
        super().__init__(_AXES * N_POINTS)
        self.gru = nn.GRU(_AXES, hidden, batch_first=True)
        self.dropout = nn.Dropout(dropout)
        self.out = nn.Linear(hidden, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """ε̂ of inputs of shape (batch, 60), shape (batch,)."""
        _, last = self.gru(self.profile(x).transpose(1, 2))
        return torch.sigmoid(self.out(self.dropout(last[-1]))).squeeze(-1)


def build_network(architecture: str, n_inputs: int, hidden: int, dropout: float) -> nn.Module:
    """An untrained candidate; ``hidden`` is the MLP's units, the CNN's filters or the GRU's state size."""
    if architecture == "cnn":
        return ConvEncoder(channels=hidden, dropout=dropout)
    if architecture == "gru":
        return GRUEncoder(hidden=hidden, dropout=dropout)
    if architecture == "mlp" or architecture in KINEMATIC_INPUTS:
        return EncoderNet(n_inputs=n_inputs, hidden=hidden, dropout=dropout)
    raise ValueError(f"unknown architecture {architecture!r}; expected one of {ARCHITECTURES}")


def as_encoder_net(network: nn.Module, *, judge: bool = False) -> EncoderNet:
    """``network`` as the :class:`EncoderNet` the blender's profile ensemble (or, with ``judge``, the judges and
    the blender's kinematic members) and the checkpoints take.

    Raises
    ------
    ValueError
        For the blender, a network that is no one-hidden-layer ReLU network of the 60 profile inputs (a
        judge-only candidate: an MLP with kinematic inputs); for either, a :class:`GRUEncoder`.
    """
    if isinstance(network, ConvEncoder):
        return network.to_encoder_net()
    if isinstance(network, EncoderNet) and (judge or network.hidden.in_features == _AXES * N_POINTS):
        return network
    gru = isinstance(network, GRUEncoder)
    role = "neither the blender's nor a shipped judge" if gru else "only a judge or a kinematic member (judge=True)"
    raise ValueError(
        f"as_encoder_net: a {type(network).__name__} of {network.mean.numel()} inputs is no EncoderNet of the 60 "
        f"profile inputs; it can be {role}"
    )


def architecture_inputs(architecture: str, profile: np.ndarray, velocity: np.ndarray, dt: float) -> np.ndarray:
    """The input matrix of ``architecture`` for movements given as resampled profiles and padded velocities.

    Parameters
    ----------
    architecture : str
        One of :data:`ARCHITECTURES`.
    profile : numpy.ndarray, shape (n, 60)
        :func:`~cogblocks.data.features.classifier_inputs` of the movements.
    velocity : numpy.ndarray, shape (n, T, 3)
        The same movements' padded velocities (for the kinematic features).
    dt : float
        Sampling step in seconds.
    """
    if architecture not in ARCHITECTURES:
        raise ValueError(f"unknown architecture {architecture!r}; expected one of {ARCHITECTURES}")
    return ensemble_inputs(profile, velocity, dt, architecture)
