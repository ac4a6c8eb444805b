"""Independent judges of an altered movement: an encoder ensemble and a kinematic classifier.

The optimised blender makes its plans satisfy the networks it constrains, so those networks'
verdict on its output says little. The judges here took no part in producing a movement:

- :class:`EncoderEnsemble`: encoder networks trained on other seeds and folds than the blender's
  (``python -m cogblocks.training.judges``); the ensemble's ε̂ is the mean of its members' ε̂,
  decided with the clipping rule (ε̂ > 0.9 fear, ε̂ < 0.1 no fear). Its networks may take the six
  kinematic features after the 60 profile inputs (:data:`KINEMATIC_INPUTS`, :func:`ensemble_inputs`).
- :class:`KinematicJudge`: a classifier of another family, a logistic regression (scikit-learn) on
  kinematic features of the movement (:func:`kinematic_features`), decided at probability 0.5:
  its probabilities are not sharp enough for the clipping rule.

:class:`Judges` groups them and scores a set of movements (:meth:`Judges.decide`).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources
from typing import Any

import numpy as np
import torch

from cogblocks.amplification.encoder import (
    FEAR,
    N_POINTS,
    NO_FEAR,
    REST_SPEED,
    UNDECIDED,
    EncoderNet,
    clip_decision,
    movement_length,
    resampling_matrix,
)
from cogblocks.sim.reading import load_torch

__all__ = [
    "FEATURES",
    "KINEMATIC_INPUTS",
    "EncoderEnsemble",
    "Judges",
    "KinematicJudge",
    "ensemble_checkpoint",
    "ensemble_inputs",
    "kinematic_features",
    "load_ensemble",
]

#: Names of the columns of :func:`kinematic_features`.
FEATURES = ("peak_speed", "time_to_peak", "duration", "log_mean_jerk", "mean_speed", "peak_fraction")

#: Ensemble architectures (a checkpoint's ``"architecture"``) whose networks take the six
#: :func:`kinematic_features` after the 60 profile inputs; ``True``: the profile divided by the peak speed.
KINEMATIC_INPUTS = {"mlp_kinematic": False, "mlp_shape_kinematic": True}

BLENDER_ENSEMBLE = "encoder_ensemble.pt"
BLENDER_KINEMATIC_ENSEMBLE = "encoder_ensemble_kinematic.pt"
JUDGE_ENSEMBLE = "judges.pt"


def kinematic_features(velocity: np.ndarray, dt: float, rest_speed: float = REST_SPEED) -> np.ndarray:
    """Kinematic features of movements, one row per movement (columns :data:`FEATURES`).

    Each movement is restricted to its own duration as the encoder restricts it
    (:func:`~cogblocks.amplification.encoder.movement_length`): peak speed (mm/s), time to peak (s),
    duration (s), log of the mean jerk magnitude (mm/s³, second difference of the velocity over dt²),
    mean speed (mm/s) and the time to peak as a share of the duration.

    Parameters
    ----------
    velocity : numpy.ndarray, shape (n, T, 3) or (T, 3)
        Velocities in mm/s, padded with zeros (or rest) after each movement.
    dt : float
        Sampling step in seconds.
    rest_speed : float
        Speed (mm/s) at or below which the hand is at rest.

    Returns
    -------
    numpy.ndarray, shape (n, 6) (or (6,) for one movement); a movement that never moves gives zeros.
    """
    v = np.asarray(velocity, dtype=np.float64)
    single = v.ndim == 2
    v = v[None] if single else v
    rows = np.zeros((len(v), len(FEATURES)))
    for i, movement in enumerate(v):
        length = movement_length(movement, rest_speed)
        if length == 0:
            continue
        speed = np.linalg.norm(movement[:length], axis=1)
        peak = int(np.argmax(speed))
        jerk = np.diff(movement[:length], n=2, axis=0) / dt**2 if length > 2 else np.zeros((1, 3))
        rows[i] = (
            speed[peak],
            peak * dt,
            length * dt,
            np.log1p(np.linalg.norm(jerk, axis=1).mean()),
            speed.mean(),
            peak / length,
        )
    return rows[0] if single else rows


def ensemble_inputs(
    profile: np.ndarray, velocity: np.ndarray, dt: float, architecture: str = "mlp", rest_speed: float = REST_SPEED
) -> np.ndarray:
    """The inputs of an ensemble of ``architecture`` for movements given by their profiles and velocities.

    Parameters
    ----------
    profile : numpy.ndarray, shape (n, 60)
        The movements restricted to their duration and resampled (the encoder's inputs).
    velocity : numpy.ndarray, shape (n, T, 3)
        The same movements' padded velocities, for :func:`kinematic_features`.
    dt : float
        Sampling step in seconds.
    architecture : str
        ``profile`` as it is for any architecture not in :data:`KINEMATIC_INPUTS`; otherwise followed
        by the kinematic features (the profile divided by the peak speed first if asked).
    rest_speed : float
        Speed (mm/s) at or below which the hand is at rest.

    Returns
    -------
    numpy.ndarray, shape (n, 60) or (n, 66)
    """
    profile = np.asarray(profile, dtype=np.float64)
    if architecture not in KINEMATIC_INPUTS:
        return profile
    features = kinematic_features(velocity, dt, rest_speed)
    if KINEMATIC_INPUTS[architecture]:
        profile = profile / np.maximum(features[:, :1], 1e-9)  # column 0: peak speed
    return np.hstack([profile, features])


class EncoderEnsemble:
    """Several :class:`EncoderNet` scoring a movement together: ε̂ is the mean of their ε̂.

    Parameters
    ----------
    networks : sequence of EncoderNet
        At least one network, all with the same number of inputs.
    architecture : str, optional
        What the networks take (:func:`ensemble_inputs`); by default the ``"architecture"`` of the
        checkpoint they were loaded from (:func:`load_ensemble`), else ``"mlp"`` (the 60 profile inputs).
    """

    def __init__(self, networks: Sequence[EncoderNet], architecture: str | None = None) -> None:
        networks = list(networks)
        if not networks or not all(isinstance(n, EncoderNet) for n in networks):
            raise ValueError("EncoderEnsemble: networks must be a non-empty sequence of EncoderNet")
        if architecture is None:
            architecture = str(getattr(networks[0], "checkpoint", {}).get("architecture", "mlp"))
        expected = 3 * N_POINTS + (len(FEATURES) if architecture in KINEMATIC_INPUTS else 0)
        sizes = sorted({n.hidden.in_features for n in networks})
        if sizes != [expected]:
            raise ValueError(f"EncoderEnsemble: {architecture!r} networks take {expected} inputs, got {sizes}")
        self.networks = networks
        self.architecture = architecture

    def __len__(self) -> int:
        return len(self.networks)

    def members(self, inputs: np.ndarray) -> np.ndarray:
        """ε̂ of every member for inputs (n, 60), or (n, 66) with kinematic inputs: shape (members, n)."""
        return np.stack([network.predict(inputs) for network in self.networks])

    def predict(self, inputs: np.ndarray) -> np.ndarray:
        """Mean ε̂ of the members for inputs (n, 60), or (n, 66) with kinematic inputs: shape (n,)."""
        return self.members(inputs).mean(axis=0)


class KinematicJudge:
    """Logistic regression on standardised :func:`kinematic_features` (scikit-learn).

    Parameters
    ----------
    dt : float
        Sampling step of the movements it will judge, in seconds.
    regularisation : float
        Inverse regularisation strength ``C`` of the logistic regression.
    """

    def __init__(self, dt: float, regularisation: float = 1.0) -> None:
        from sklearn.linear_model import LogisticRegression
        from sklearn.pipeline import make_pipeline
        from sklearn.preprocessing import StandardScaler

        self.dt = float(dt)
        self.model = make_pipeline(StandardScaler(), LogisticRegression(C=regularisation, max_iter=1000))

    def fit(self, velocity: np.ndarray, fear: np.ndarray) -> KinematicJudge:
        """Fit on padded velocities (n, T, 3) and boolean labels (n,); both classes must occur."""
        labels = np.asarray(fear, dtype=bool)
        if labels.all() or not labels.any():
            raise ValueError("KinematicJudge.fit: the training movements must hold both fear and no-fear examples")
        self.model.fit(kinematic_features(velocity, self.dt), labels)
        return self

    def predict(self, velocity: np.ndarray) -> np.ndarray:
        """Probability of fear of padded velocities (n, T, 3): shape (n,)."""
        return self.model.predict_proba(kinematic_features(velocity, self.dt))[:, 1]


@dataclass
class Judges:
    """The independent judges of a validation run.

    Attributes
    ----------
    ensemble : EncoderEnsemble
        Networks disjoint from those the blender uses.
    kinematic : KinematicJudge
        Fitted on the same training movements.
    """

    ensemble: EncoderEnsemble
    kinematic: KinematicJudge

    def decide(self, velocity: np.ndarray, rest_speed: float = REST_SPEED) -> dict[str, np.ndarray]:
        """Decisions (1 fear, 0 no fear, −1 undecided) of each judge on padded velocities (n, T, 3).

        The ensemble classifies each movement restricted and resampled as the online classifier
        does (followed by its kinematic features if its architecture takes them); ``"ensemble"`` uses
        the clipping rule on the mean ε̂, ``"kinematic"`` decides at 0.5.
        """
        v = np.asarray(velocity, dtype=np.float64)
        inputs = np.zeros((len(v), 3 * N_POINTS))
        moved = np.zeros(len(v), dtype=bool)
        for i, movement in enumerate(v):
            length = movement_length(movement, rest_speed)
            if length:
                inputs[i] = (resampling_matrix(length) @ movement[:length]).T.reshape(-1)
                moved[i] = True
        inputs = ensemble_inputs(inputs, v, self.kinematic.dt, self.ensemble.architecture, rest_speed)
        ensemble = np.where(moved, clip_decision(self.ensemble.predict(inputs)), UNDECIDED)
        kinematic = np.where(moved, np.where(self.kinematic.predict(v) > 0.5, FEAR, NO_FEAR), UNDECIDED)
        return {"ensemble": ensemble, "kinematic": kinematic}


def ensemble_checkpoint(networks: Sequence[EncoderNet], **meta: Any) -> dict[str, Any]:
    """A checkpoint of several encoder networks, weights in float16 (a quarter of the float64 size)."""
    first = networks[0]
    return {
        "state_dicts": [{k: v.detach().half() for k, v in n.state_dict().items()} for n in networks],
        "hidden": first.hidden.out_features,
        "inputs": first.hidden.in_features,
        **meta,
    }


def load_ensemble(name_or_path: str | os.PathLike) -> list[EncoderNet]:
    """Networks of a checkpoint written with :func:`ensemble_checkpoint`, in evaluation mode.

    Parameters
    ----------
    name_or_path : str or path-like
        ``"encoder_ensemble.pt"`` (the blender's), ``"encoder_ensemble_kinematic.pt"`` (the blender's
        kinematic networks), ``"judges.pt"`` (the judges') in the shipped
        weights, or a path. The metadata is in each network's ``checkpoint`` attribute.
    """
    if str(name_or_path) in (BLENDER_ENSEMBLE, BLENDER_KINEMATIC_ENSEMBLE, JUDGE_ENSEMBLE):
        with resources.as_file(resources.files("cogblocks.data") / "weights" / str(name_or_path)) as p:
            checkpoint = torch.load(p, weights_only=True)
    else:
        checkpoint = load_torch(name_or_path, "network ensemble checkpoint", keys=("inputs", "hidden", "state_dicts"))
    meta = {k: v for k, v in checkpoint.items() if k != "state_dicts"}
    networks = []
    for state in checkpoint["state_dicts"]:
        network = EncoderNet(n_inputs=checkpoint["inputs"], hidden=checkpoint["hidden"])
        network.load_state_dict({k: v.float() for k, v in state.items()})
        network.eval()
        network.checkpoint = meta
        networks.append(network)
    return networks
