"""Realistic directions for the optimised blender: a PCA of one class's classifier inputs.

Unrestricted, :class:`~cogblocks.amplification.OptimalBlender` finds corrections that satisfy the
networks it constrains by moving the classifier input off the data (docs/validation/amplification.md):
independently trained networks do not follow. A :class:`MovementSubspace` holds the mean and the
leading principal directions of the classifier inputs (20 resampled points per axis, as
:func:`cogblocks.data.features.classifier_inputs`) of the library's movements of the desired class;
the blender then only moves the altered movement's classifier input along these directions, the
ways in which real movements of that class differ from one another.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cogblocks.data.features import classifier_inputs
from cogblocks.data.reach import ReachLibrary
from cogblocks.sim.params import one_of, positive_int

__all__ = ["MovementSubspace", "checked_subspace", "load_subspace", "movement_subspace"]


@dataclass(frozen=True)
class MovementSubspace:
    """The leading principal directions of the classifier inputs of one class.

    Attributes
    ----------
    mean : numpy.ndarray, shape (n_inputs,)
        Mean classifier input of the class (mm/s).
    components : numpy.ndarray, shape (k, n_inputs)
        Orthonormal principal directions, by decreasing variance.
    explained : float
        Share of the class's variance the ``k`` directions explain.
    e_des : int
        The class: 1 fear, 0 no fear.
    """

    mean: np.ndarray
    components: np.ndarray
    explained: float
    e_des: int

    def __post_init__(self) -> None:
        components = np.asarray(self.components, dtype=np.float64)
        if components.ndim != 2 or components.shape[1] != len(self.mean) or len(components) < 1:
            raise ValueError(f"MovementSubspace: components must be (k ≥ 1, {len(self.mean)}), got {components.shape}")
        if not np.allclose(components @ components.T, np.eye(len(components)), atol=1e-6):
            raise ValueError("MovementSubspace: components must be orthonormal rows")

    def __len__(self) -> int:
        return len(self.components)

    def residual(self, inputs: np.ndarray) -> np.ndarray:
        """Distance (mm/s) of classifier inputs (..., n_inputs) from the affine subspace: shape (...)."""
        centred = np.asarray(inputs, dtype=np.float64) - self.mean
        return np.linalg.norm(centred - (centred @ self.components.T) @ self.components, axis=-1)

    def penalty(self, inputs_map: np.ndarray, offset: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The squared residual of affine inputs ``x = offset + A w`` as ``wᵀ H w + 2 qᵀ w + const``: (H, q).

        ``inputs_map`` is ``A``; the residual is the part of ``x − mean`` outside the subspace, so
        ``H = AᵀQA`` and ``q = AᵀQ(offset − mean)`` with ``Q`` the projector onto its complement.
        """
        a = np.asarray(inputs_map, dtype=np.float64)
        qa = a - self.components.T @ (self.components @ a)  # Q A
        centred = np.asarray(offset, dtype=np.float64) - self.mean
        return qa.T @ qa, qa.T @ (centred - self.components.T @ (self.components @ centred))

    def save(self, path: str | os.PathLike) -> None:
        """Write the subspace to an ``.npz`` file (:func:`load_subspace` reads it)."""
        np.savez(Path(path), mean=self.mean, components=self.components, explained=self.explained, e_des=self.e_des)


def movement_subspace(library: ReachLibrary, e_des: int, components: int = 8) -> MovementSubspace:
    """The PCA of the classifier inputs of ``library``'s movements of class ``e_des``.

    Parameters
    ----------
    library : ReachLibrary
        The blender's library (the training part: never the movements it will be validated on).
    e_des : {0, 1}
        The class whose movements span the subspace (the class the blender is asked to encode).
    components : int
        Number of principal directions kept (at most the number of movements of the class).
    """
    if not isinstance(library, ReachLibrary):
        raise ValueError(f"movement_subspace: library must be a ReachLibrary, got {type(library).__name__}")
    e_des = one_of("movement_subspace", "e_des", e_des, (0, 1))
    components = positive_int("movement_subspace", "components", components)
    inputs = classifier_inputs(library)[library.fear == bool(e_des)]
    if len(inputs) < components:
        raise ValueError(
            f"movement_subspace: {components} components need at least as many movements of class "
            f"e_des={e_des}, the library has {len(inputs)}"
        )
    mean = inputs.mean(axis=0)
    _, singular, directions = np.linalg.svd(inputs - mean, full_matrices=False)
    variance = singular**2
    explained = float(variance[:components].sum() / variance.sum()) if variance.sum() > 0 else 1.0
    return MovementSubspace(mean, directions[:components], explained, e_des)


def load_subspace(path: str | os.PathLike) -> MovementSubspace:
    """A subspace written by :meth:`MovementSubspace.save`."""
    from cogblocks.sim.reading import open_npz

    with open_npz(path, "MovementSubspace") as data:
        missing = {"mean", "components", "explained", "e_des"} - set(data.files)
        if missing:
            raise ValueError(f"{path}: not a MovementSubspace file (missing {', '.join(sorted(missing))})")
        return MovementSubspace(data["mean"], data["components"], float(data["explained"]), int(data["e_des"]))


def checked_subspace(owner: str, subspace: object, e_des: int, n_inputs: int) -> MovementSubspace | None:
    """``subspace`` if ``None`` or a :class:`MovementSubspace` of ``n_inputs`` inputs for ``e_des``; else an error."""
    if subspace is None or (
        isinstance(subspace, MovementSubspace) and subspace.e_des == e_des and len(subspace.mean) == n_inputs
    ):
        return subspace
    raise ValueError(
        f"{owner}: subspace must be a MovementSubspace of {n_inputs} inputs for e_des={e_des}, got "
        f"{type(subspace).__name__} (e_des={getattr(subspace, 'e_des', None)})"
    )
