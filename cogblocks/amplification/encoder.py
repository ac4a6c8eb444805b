"""The encoder of the PoP of Amplification: the fear classifier network and its block."""

from __future__ import annotations

import math
import os
from functools import lru_cache
from importlib import resources
from typing import Any

import numpy as np
import torch
from torch import nn

from cogblocks.amplification.buffer import ordered_window
from cogblocks.blocks.samples import plausible
from cogblocks.blocks.specs import COUNT
from cogblocks.data.features import resample_movement
from cogblocks.sim import Block, Signal
from cogblocks.sim.params import finite_number
from cogblocks.sim.reading import load_torch

__all__ = [
    "CLIP_HIGH",
    "CLIP_LOW",
    "EncoderClassifier",
    "EncoderNet",
    "FEAR",
    "NO_FEAR",
    "REST_SPEED",
    "StandardisedNet",
    "UNDECIDED",
    "clip_decision",
    "load_encoder",
    "movement_length",
    "resampling_matrix",
]

FEAR, NO_FEAR, UNDECIDED = 1, 0, -1
CLIP_HIGH, CLIP_LOW = 0.9, 0.1
N_POINTS = 20  # resampled points per axis: 60 classifier inputs
REST_SPEED = 1.0  # mm/s: a movement has ended once the hand stays at or below this speed

ENCODER_WEIGHTS = "encoder.pt"


def clip_decision(eps_hat: Any) -> np.ndarray:
    """The clipping rule: ``FEAR`` (1) above 0.9, ``NO_FEAR`` (0) below 0.1, ``UNDECIDED`` (−1) between.

    Parameters
    ----------
    eps_hat : array_like
        Classifier outputs in [0, 1]. NaN is undecided.

    Returns
    -------
    numpy.ndarray of int64, the shape of ``eps_hat``
    """
    eps = np.asarray(eps_hat, dtype=np.float64)
    decision = np.full(eps.shape, UNDECIDED, dtype=np.int64)
    decision[eps > CLIP_HIGH] = FEAR
    decision[eps < CLIP_LOW] = NO_FEAR
    return decision


class StandardisedNet(nn.Module):
    """A network whose inputs are standardised with a per-input mean and scale kept in its buffers.

    The saved weights thus carry their own normalisation (:meth:`set_normalisation`); :meth:`predict`
    evaluates the network on NumPy arrays. Subclasses define ``forward``.

    Parameters
    ----------
    n_inputs : int
        Number of inputs.
    """

    def __init__(self, n_inputs: int) -> None:
        super().__init__()
        self.register_buffer("mean", torch.zeros(n_inputs))
        self.register_buffer("scale", torch.ones(n_inputs))

    def set_normalisation(self, inputs: np.ndarray) -> None:
        """Standardise inputs with the mean and standard deviation of ``inputs`` (n, n_inputs)."""
        x = np.asarray(inputs, dtype=np.float64)
        std = x.std(axis=0)
        self.mean.copy_(torch.as_tensor(x.mean(axis=0)))
        self.scale.copy_(torch.as_tensor(np.where(std > 0, std, 1.0)))

    def predict(self, inputs: np.ndarray) -> np.ndarray:
        """ε̂ of a NumPy array of inputs (..., n_inputs), in evaluation mode, as float64."""
        was_training = self.training
        self.eval()
        try:
            with torch.no_grad():
                dtype = next(self.parameters()).dtype
                return self(torch.as_tensor(np.asarray(inputs), dtype=dtype)).double().numpy()
        finally:
            self.train(was_training)


class EncoderNet(StandardisedNet):
    """The approximate encoding function ε̂: 60 inputs → 200 ReLU units with dropout → 1 sigmoid.

    The inputs (20 resampled velocity points per axis, axis-major, mm/s) are standardised with a
    per-input mean and scale stored in the network's buffers, so that the saved weights carry their
    own normalisation (:meth:`set_normalisation`).

    Parameters
    ----------
    n_inputs : int
        Number of inputs (60).
    hidden : int
        Hidden ReLU units (200).
    dropout : float
        Dropout probability on the hidden units during training.
    """

    def __init__(self, n_inputs: int = 3 * N_POINTS, hidden: int = 200, dropout: float = 0.2) -> None:
        super().__init__(n_inputs)
        self.hidden = nn.Linear(n_inputs, hidden)
        self.dropout = nn.Dropout(dropout)
        self.out = nn.Linear(hidden, 1)

    def preactivation(self, x: torch.Tensor) -> torch.Tensor:
        """Hidden pre-activations, an affine function of the inputs: shape (..., hidden)."""
        return self.hidden((x - self.mean) / self.scale)

    def head(self, pre: torch.Tensor) -> torch.Tensor:
        """ε̂ from hidden pre-activations: shape (...,)."""
        return torch.sigmoid(self.out(self.dropout(torch.relu(pre)))).squeeze(-1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """ε̂ of inputs of shape (..., 60), shape (...,)."""
        return self.head(self.preactivation(x))


def load_encoder(path: str | os.PathLike | None = None) -> EncoderNet:
    """Load an :class:`EncoderNet` saved by ``python -m cogblocks.training.encoder``.

    Parameters
    ----------
    path : path-like, optional
        The checkpoint; the shipped ``cogblocks/data/weights/encoder.pt`` by default.

    Returns
    -------
    EncoderNet
        In evaluation mode; the checkpoint's metadata (split, cross-validation) is in
        ``network.checkpoint``.
    """
    checkpoint = _load_checkpoint(path)
    network = EncoderNet(hidden=checkpoint["hidden"], dropout=checkpoint["dropout"])
    network.load_state_dict(checkpoint["state_dict"])
    network.eval()
    network.checkpoint = {k: v for k, v in checkpoint.items() if k != "state_dict"}
    return network


def _load_checkpoint(path: str | os.PathLike | None) -> dict[str, Any]:
    if path is None:
        with resources.as_file(resources.files("cogblocks.data") / "weights" / ENCODER_WEIGHTS) as p:
            return torch.load(p, weights_only=True)
    return load_torch(path, "encoder checkpoint", keys=("hidden", "dropout", "state_dict"))


def movement_length(velocity: np.ndarray, rest_speed: float) -> int:
    """Samples of a movement up to its last one faster than ``rest_speed`` (0 if none is).

    This is the restriction of a buffered or padded movement to its own duration: what follows
    is the rest after the terminal instant.
    """
    moving = np.flatnonzero(np.linalg.norm(velocity, axis=1) > rest_speed)
    return int(moving[-1]) + 1 if moving.size else 0


@lru_cache(maxsize=1024)
def resampling_matrix(length: int, n_points: int = N_POINTS) -> np.ndarray:
    """The linear map of :func:`~cogblocks.data.features.resample_movement` for one length (read-only).

    Resampling a signal of ``length`` samples is linear in the samples, so it is a matrix
    ``R`` of shape ``(n_points, length)`` with ``resampled = R @ samples``: what lets w̃ be computed
    on all pairs at once, and the online classifier skip fitting a spline at every tick.
    """
    matrix = resample_movement(np.eye(length), length, n_points).reshape(length, n_points).T.copy()
    matrix.flags.writeable = False
    return matrix


# --- blocks -----------------------------------------------------------------------------------------


class EncoderClassifier(Block):
    """ε̂ and the clipped decision of a buffered movement, recomputed at every run of the block.

    The buffered samples (oldest first) are restricted to the movement's own duration, up to the
    last sample faster than ``rest_speed`` (:func:`movement_length`), resampled to 20 points per axis
    and classified.

    Ports
    -----
    velocity : input, shape (capacity, 3), mm/s
        A velocity ring from :class:`~cogblocks.amplification.Buffer`.
    count : input, int64
        Samples received by the buffer.
    eps : output, scalar
        ε̂ in [0, 1]; NaN until the movement has started.
    decision : output, int64
        :func:`clip_decision` of ``eps``: 1 fear, 0 no fear, −1 undecided.
    length : output, int64
        Samples classified (the restricted length).

    Parameters
    ----------
    network : EncoderNet
        The classifier.
    rest_speed : float
        Speed (mm/s, >= 0) at or below which the hand is at rest.

    Notes
    -----
    With samples lost off the start of a full ring, what is classified is the newest ``capacity``
    samples.

    Bad data policy: the buffer upstream replaces non-finite and implausible samples; fed
    directly, a window holding a sample beyond 1 km/s
    (:func:`~cogblocks.blocks.samples.plausible`) is not classified and the outputs hold.

    It runs a batch at once: each run's window is restricted and resampled on its own, the network
    evaluates every run's features in one product (the same value as one run's to rounding).
    """

    batchable = True

    def __init__(self, network: EncoderNet, *, rest_speed: float = REST_SPEED, period: float | None = None) -> None:
        super().__init__(period=period)
        if not isinstance(network, EncoderNet):
            raise ValueError(f"EncoderClassifier: network must be an EncoderNet, got {type(network).__name__}")
        self.rest_speed = finite_number(self, "rest_speed", rest_speed, low=0.0)
        # NumPy copies of the weights: one 60-input evaluation per tick costs far less without torch
        state = {k: v.detach().double().numpy() for k, v in network.state_dict().items()}
        self._mean, self._scale = state["mean"], state["scale"]
        self._w1, self._b1 = state["hidden.weight"], state["hidden.bias"]
        self._w2, self._b2 = state["out.weight"][0], float(state["out.bias"][0])
        self.add_input("velocity", Signal(shape=None, unit="mm/s"))
        self.add_input("count", COUNT)
        self.add_output("eps", Signal(unit="1"), initial=math.nan)
        self.add_output("decision", COUNT, initial=UNDECIDED)
        self.add_output("length", COUNT)

    def setup(self) -> None:
        shape = self.velocity.spec.shape
        if len(shape) != 2 or shape[1] != 3:
            raise self._fail(f"velocity must have shape (capacity, 3), got {shape}")

    def classify(self, velocity: np.ndarray) -> tuple[float, int]:
        """ε̂ and the restricted length of a movement given oldest sample first, shape (n, 3)."""
        length = movement_length(velocity, self.rest_speed)
        if length == 0:
            return math.nan, 0
        x = ((resampling_matrix(length) @ velocity[:length]).T.reshape(-1) - self._mean) / self._scale
        z = float(self._w2 @ np.maximum(self._w1 @ x + self._b1, 0.0) + self._b2)
        e = math.exp(-abs(z))  # the sigmoid without overflow for large |z|
        return (1.0 / (1.0 + e) if z >= 0 else e / (1.0 + e)), length

    def _output_rows(self) -> None:
        rows, features = [], []
        for b, (ring, count) in enumerate(zip(self.velocity.value, self.count.value, strict=True)):
            window = ordered_window(ring, int(count))
            if not plausible(window):
                continue  # this run's outputs hold
            length = movement_length(window, self.rest_speed)
            self.length.value[b] = length
            if length == 0:
                self.eps.value[b], self.decision.value[b] = math.nan, clip_decision(math.nan)
                continue
            rows.append(b)
            features.append((resampling_matrix(length) @ window[:length]).T.reshape(-1))
        if rows:
            x = (np.array(features) - self._mean) / self._scale
            z = np.maximum(x @ self._w1.T + self._b1, 0.0) @ self._w2 + self._b2
            e = np.exp(-np.abs(z))  # the sigmoid without overflow for large |z|
            eps = np.where(z >= 0, 1.0 / (1.0 + e), e / (1.0 + e))
            self.eps.value[rows] = eps
            self.decision.value[rows] = clip_decision(eps)

    def output(self, k: int) -> None:
        if self.batch is not None:
            self._output_rows()
            return
        window = ordered_window(self.velocity.value, int(self.count.value))
        if not plausible(window):
            return
        eps, length = self.classify(window)
        self.eps.value[...] = eps
        self.decision.value[...] = clip_decision(eps)
        self.length.value[...] = length
