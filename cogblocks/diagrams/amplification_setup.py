"""The data and models of the PoP of Amplification's validation: library, split, encoder, w̃ and judges."""

from __future__ import annotations

import inspect
import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from cogblocks.amplification import EncoderNet, OptimalBlender, SolutionTable, load_encoder, solution_table
from cogblocks.amplification.judges import (
    BLENDER_ENSEMBLE,
    BLENDER_KINEMATIC_ENSEMBLE,
    JUDGE_ENSEMBLE,
    EncoderEnsemble,
    Judges,
    KinematicJudge,
    load_ensemble,
)
from cogblocks.amplification.smoothing import STEP_LIMIT
from cogblocks.amplification.solution import library_fingerprint, same_library
from cogblocks.amplification.subspace import MovementSubspace, movement_subspace
from cogblocks.data.reach import ReachLibrary, generate_reach_library

__all__ = [
    "BLENDER_WITH_ENCODER",
    "COMPONENTS",
    "CONSTRAINED_MEMBERS",
    "OPTIMISED",
    "STEP_LIMIT",
    "AmplificationSetup",
    "amplification_judges",
    "amplification_setup",
    "blender_ensembles",
    "blender_networks",
    "judged_shares",
    "optimised_subspace",
]

#: Principal directions of the desired class the shipped optimised blender's realism subspace keeps.
COMPONENTS = 12

#: The shipped optimised blender's settings: :class:`~cogblocks.amplification.OptimalBlender`'s own defaults (its
#: docstring says what they are and why), and ``components`` of its realism subspace (:func:`optimised_subspace`).
#: Derived from the class, so the two cannot disagree.
OPTIMISED = {
    **{
        name: inspect.signature(OptimalBlender).parameters[name].default
        for name in (
            "solver",
            "time_limit_ms",
            "solve_ticks",
            "iterations",
            "realism",
            "margin",
            "removal_margin",
            "emit",
            "guard_rest",
            "neighbours",
            "terminal_margin",
        )
    },
    "components": COMPONENTS,
}

#: Whether the optimised blender constrains the shipped encoder too, besides the blender ensemble
#: (``encoder_ensemble.pt``, trained with the judges' recipe).
BLENDER_WITH_ENCODER = True

#: How many networks of each shipped blender ensemble the optimised blender constrains: ``"profile"`` of
#: ``encoder_ensemble.pt`` (60 profile inputs), ``"kinematic"`` of ``encoder_ensemble_kinematic.pt``
#: (``mlp_kinematic``: the profile and the six kinematic features). On the inner split the four kinematic
#: networks joining the two profile ones made the plans convince the judges more often
#: (docs/validation/amplification.md).
CONSTRAINED_MEMBERS = {"profile": 2, "kinematic": 4}


def blender_networks(
    encoder: EncoderNet,
    profile: int | None = None,
    kinematic: int | None = None,
    ensembles: tuple[Sequence[EncoderNet], Sequence[EncoderNet]] | None = None,
) -> list[EncoderNet]:
    """The networks the optimised blender constrains: ``encoder`` (see :data:`BLENDER_WITH_ENCODER`), then the
    first ``profile`` and ``kinematic`` networks of the blender's profile and kinematic ensembles (by default
    :data:`CONSTRAINED_MEMBERS`; the shipped ``encoder_ensemble.pt`` and ``encoder_ensemble_kinematic.pt``
    unless ``ensembles`` gives others, as :func:`cogblocks.training.pipeline.run_pipeline` does)."""
    profile = CONSTRAINED_MEMBERS["profile"] if profile is None else profile
    kinematic = CONSTRAINED_MEMBERS["kinematic"] if kinematic is None else kinematic
    if ensembles is None:
        ensembles = (load_ensemble(BLENDER_ENSEMBLE), load_ensemble(BLENDER_KINEMATIC_ENSEMBLE) if kinematic else [])
    return [*([encoder] if BLENDER_WITH_ENCODER else []), *ensembles[0][:profile], *ensembles[1][:kinematic]]


def blender_ensembles(
    kinematic_weights: Sequence[str | os.PathLike] = (BLENDER_KINEMATIC_ENSEMBLE,),
) -> tuple[list[EncoderNet], list[EncoderNet]]:
    """The blender's profile ensemble (``encoder_ensemble.pt``) and its kinematic networks, those of every file of
    ``kinematic_weights`` in order (by default the shipped ``encoder_ensemble_kinematic.pt``): the ``ensembles``
    of :func:`blender_networks`, so that the experiments may try kinematic networks that are not shipped."""
    return load_ensemble(BLENDER_ENSEMBLE), [network for path in kinematic_weights for network in load_ensemble(path)]


@dataclass(frozen=True)
class AmplificationSetup:
    """The data and models of a validation run.

    Attributes
    ----------
    library : ReachLibrary
        The whole synthetic library.
    train, val : numpy.ndarray of int
        The 70/30 split: the projector searches ``movements`` (the training part), the humans
        replayed are taken from the validation part.
    movements : ReachLibrary
        ``library.subset(train)``.
    encoder : EncoderNet
    table : SolutionTable
        w̃ on ``movements``.
    e_des : int
    subspace : MovementSubspace, optional
        The realistic directions of the optimised blender (:func:`movement_subspace` of ``movements``
        for ``e_des``); built by :func:`optimised_subspace` when absent.
    """

    library: ReachLibrary
    train: np.ndarray
    val: np.ndarray
    movements: ReachLibrary
    encoder: EncoderNet
    table: SolutionTable
    e_des: int
    subspace: MovementSubspace | None = None

    @property
    def humans(self) -> np.ndarray:
        """Library indices of the validation movements that do not encode ``e_des``."""
        return self.val[self.library.fear[self.val] != bool(self.e_des)]


def _trained_on(meta: dict, library: ReachLibrary) -> bool:
    """Whether the checkpoint's metadata ``meta`` says it was trained on ``library`` (or says nothing of it).

    Bit for bit (``library_sha256``), or else to rounding (``library_summary``, where the checkpoint has one): the
    generator's last bits differ between CPUs and NumPy / SciPy builds, its content does not.
    """
    if meta.get("library_sha256") in (None, library_fingerprint(library)):
        return True
    return "library_summary" in meta and same_library(meta["library_summary"], library)


@lru_cache(maxsize=4)
def amplification_setup(seed: int | None = None, e_des: int = 1) -> AmplificationSetup:
    """The shipped encoder, its library, a seeded 70/30 split and w̃ on the training part.

    Parameters
    ----------
    seed : int, optional
        Seed of ``ReachLibrary.split``; by default the split the shipped encoder was validated on,
        so that no replayed movement was used to train it.
    e_des : {0, 1}
        Desired encoding level.
    """
    encoder = load_encoder()
    meta = encoder.checkpoint
    library = generate_reach_library(int(meta["library_seed"]))
    if not _trained_on(meta, library):
        warnings.warn(
            "the synthetic library differs from the one the shipped encoder was trained on (the generator "
            "changed): retrain with `python -m cogblocks.training.encoder --seed 0 --out "
            "cogblocks/data/weights/encoder.pt` and `python -m cogblocks.training.corrector --seed 0 --out "
            "cogblocks/data/weights/corrector.pt`",
            UserWarning,
            stacklevel=2,
        )
    split_seed = int(meta["split_seed"]) if seed is None else seed
    train, val = library.split(float(meta["val_fraction"]), split_seed)
    movements = library.subset(train)
    table = solution_table(encoder, movements, e_des)
    return AmplificationSetup(
        library, train, val, movements, encoder, table, e_des, optimised_subspace(movements, e_des)
    )


def optimised_subspace(movements: ReachLibrary, e_des: int) -> MovementSubspace:
    """The optimised blender's subspace: the PCA of ``movements`` of class ``e_des`` (:data:`OPTIMISED`).

    A class with fewer movements than ``COMPONENTS`` keeps as many directions as it has movements.
    """
    count = int(np.sum(movements.fear == bool(e_des)))
    return movement_subspace(movements, e_des, max(1, min(COMPONENTS, count)))


@lru_cache(maxsize=1)
def amplification_judges() -> Judges:
    """The independent judges of the shipped split: the shipped judge ensemble (``judges.pt``) and a
    :class:`KinematicJudge` fitted on the split's training part (neither saw a validation movement)."""
    setup = amplification_setup(None, 1)
    train = setup.movements
    kinematic = KinematicJudge(setup.library.dt).fit(train.velocity, train.fear)
    return Judges(EncoderEnsemble(load_ensemble(JUDGE_ENSEMBLE)), kinematic)


def judged_shares(judges: Judges, altered: list[np.ndarray], e_des: int) -> dict[str, Any]:
    """The independent judges on the altered movements: ``judges`` (share each decides as ``e_des``),
    ``encoded_independent`` (the ensemble judge's share) and ``judges_agreement`` (share on which they agree)."""
    if not altered:
        return {"judges": {}, "encoded_independent": float("nan"), "judges_agreement": float("nan")}
    verdicts = {name: d == e_des for name, d in judges.decide(np.stack(altered)).items()}
    return {
        "judges": {name: float(v.mean()) for name, v in verdicts.items()},
        "encoded_independent": float(verdicts["ensemble"].mean()),
        "judges_agreement": float(np.mean(verdicts["ensemble"] == verdicts["kinematic"])),
    }
