"""The whole PoP of Amplification chain on a user's own library, in one call.

Usage::

    cogblocks run amplification --library FILE --out DIR [--quick] [--seed 0] [--label-field NAME] [--dt SECONDS]

:func:`run_pipeline` loads the library (``.mat`` VelocityData, ``.npz`` or ``.csv``, see
:mod:`cogblocks.data.loaders`), splits it (seeded, stratified, 30 % held out), trains the encoder with
5-fold cross-validation on the training part, the blender's other networks and the judges' ensemble
(:mod:`cogblocks.training.judges`), fits the kinematic judge, computes w̃ for both directions,
trains the RL corrector and validates every variant in both directions on the held-out part. Weights,
tables and a JSON report go to ``out_dir``. ``quick`` shortens the training (5 encoder epochs, 60
corrector episodes) for a first look.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from cogblocks.amplification import solution_table
from cogblocks.amplification.judges import EncoderEnsemble, Judges, KinematicJudge, ensemble_checkpoint
from cogblocks.amplification.smoothing import STEP_LIMIT
from cogblocks.amplification.solution import library_fingerprint
from cogblocks.data.features import classifier_inputs
from cogblocks.data.loaders import load_csv, load_npz, load_velocity_data_mat
from cogblocks.data.reach import ReachLibrary
from cogblocks.diagrams.amplification import run_amplification
from cogblocks.diagrams.amplification_setup import AmplificationSetup, blender_networks, optimised_subspace
from cogblocks.sim.timing import BASE_STEP
from cogblocks.training.amplification_env import record_episodes
from cogblocks.training.corrector import CorrectorConfig, train
from cogblocks.training.encoder import EncoderConfig, cross_validate
from cogblocks.training.judges import (
    BLENDER_KINEMATIC_MEMBERS,
    BLENDER_MEMBERS,
    train_blender_ensemble,
    train_blender_kinematic,
    train_judges,
)
from cogblocks.training.recipe import CHOSEN, JUDGE_CHOSEN, RECIPES

__all__ = ["DIRECTIONS", "load_library", "run_pipeline"]

#: The two directions validated: the key in the report and ``e_des``.
DIRECTIONS = {"encode": 1, "remove": 0}
VAL_FRACTION = 0.3


def load_library(
    path: str | os.PathLike,
    *,
    label_field: str | None = None,
    dt: float | None = None,
    max_len: int = 200,
    unit: str | None = None,
) -> ReachLibrary:
    """Load a library by its suffix: ``.mat`` (VelocityData), ``.npz`` or ``.csv``.

    Parameters
    ----------
    path : path-like
        The file.
    label_field : str, optional
        Name of the fear label (default ``Condition`` in ``.mat``, ``fear`` otherwise).
    dt : float, optional
        Sampling step in seconds (default: the ``.npz`` file's, 0.01 s for ``.mat`` and ``.csv``).
    max_len : int
        Padded samples per movement.
    unit : {"mm", "cm", "m"}, optional
        Length unit of the file's positions and velocities (per second), converted to mm (default:
        an ``.npz`` file's ``unit`` key, mm otherwise).
    """
    if Path(path).is_dir():
        raise ValueError(f"{path} is a folder: give a library file (.mat, .npz or .csv)")
    suffix = Path(path).suffix.lower()
    if suffix == ".mat":
        step = BASE_STEP if dt is None else dt
        return load_velocity_data_mat(path, max_len, step, label_field=label_field or "Condition", unit=unit or "mm")
    if suffix == ".npz":
        return load_npz(path, label_field=label_field or "fear", dt=dt, unit=unit)
    if suffix == ".csv":
        step = BASE_STEP if dt is None else dt
        return load_csv(path, max_len, step, label_field=label_field or "fear", unit=unit or "mm")
    raise ValueError(f"{path}: unknown library format '{suffix}' (expected .mat, .npz or .csv)")


def _speed(library: ReachLibrary) -> dict[str, float]:
    """The RMS speed of the movements' samples in mm/s: a file read in the wrong unit shows here."""
    moving = np.arange(library.velocity.shape[1]) < np.asarray(library.length)[:, None]
    speed = np.linalg.norm(library.velocity, axis=-1)[moving]
    return {"speed_rms_mm_s": float(np.sqrt(np.mean(speed**2)))}


def run_pipeline(
    library: ReachLibrary | str | os.PathLike,
    out_dir: str | os.PathLike,
    seed: int = 0,
    quick: bool = False,
    *,
    label_field: str | None = None,
    dt: float | None = None,
    unit: str | None = None,
    limit: int | None = None,
    encoder_epochs: int | None = None,
    corrector_episodes: int | None = None,
    step_limit: float | None = STEP_LIMIT,
    log: Callable[[str], None] | None = print,
) -> dict[str, Any]:
    """Train and validate the whole chain on ``library``; write its products to ``out_dir``.

    Parameters
    ----------
    library : ReachLibrary or path-like
        The movements, or a file for :func:`load_library`.
    out_dir : path-like
        Created if needed; receives ``encoder.pt``, ``encoder_ensemble.pt``, ``encoder_ensemble_kinematic.pt``,
        ``judges.pt``,
        ``corrector.pt``, ``w_tilde_encode.npz``, ``w_tilde_remove.npz``, the optimised blender's
        subspaces ``subspace_encode.npz`` and ``subspace_remove.npz``
        (:func:`cogblocks.amplification.subspace.load_subspace`) and
        ``report.json``.
    seed : int
        Seeds the split, every network and the corrector's training.
    quick : bool
        5 encoder epochs and 60 corrector episodes instead of 40 and 1100.
    label_field, dt, unit : see :func:`load_library` (``unit``: the file's length unit, converted to mm).
    limit : int, optional
        Validate only the first ``limit`` held-out movements per direction.
    encoder_epochs, corrector_episodes : int, optional
        Override the training lengths (tests train tiny models).
    step_limit : float, optional
        The validation runs' step limit (:func:`~cogblocks.diagrams.amplification.run_amplification`'s; the
        ready diagrams' by default, None: none).
    log : callable, optional
        Receives the progress lines; ``None`` is silent.

    Returns
    -------
    dict
        The report written to ``report.json``: ``library`` (counts, dt, fingerprint), ``split``,
        ``encoder_cv``, ``judge_accuracy`` (each judge's accuracy on the held-out movements, as
        recorded) and ``directions`` (``"encode"`` and ``"remove"``: :func:`run_amplification`'s
        result per variant).
    """
    say = log or (lambda _: None)
    started = time.perf_counter()
    if not isinstance(library, ReachLibrary):
        library = load_library(library, label_field=label_field, dt=dt, unit=unit)
    counts = {"fear": int(library.fear.sum()), "no_fear": int((~library.fear).sum())}
    if min(counts.values()) < 10:
        raise ValueError(f"run_pipeline: each class needs at least 10 movements, got {counts}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(1)
    train_idx, val_idx = library.split(VAL_FRACTION, seed)
    movements = library.subset(train_idx)
    say(f"library: {len(library)} movements ({counts}); {len(train_idx)} for training, {len(val_idx)} held out")

    epochs = encoder_epochs or (5 if quick else EncoderConfig.epochs)
    config = EncoderConfig(epochs=epochs)
    say(f"encoder: 5-fold cross-validation on the training part ({epochs} epochs)")
    folds = cross_validate(config, seed, library=movements, log=say)
    best = max(folds, key=lambda r: r.accuracy)
    encoder = best.network
    recipe, judge_recipe = (
        (RECIPES[CHOSEN], RECIPES[JUDGE_CHOSEN])
        if not (quick or encoder_epochs)
        else (replace(RECIPES[CHOSEN], epochs=epochs), replace(RECIPES[JUDGE_CHOSEN], epochs=epochs))
    )
    say(f"blender ensembles ('{CHOSEN}', '{JUDGE_CHOSEN}'), judges ('{JUDGE_CHOSEN}'), at most {recipe.epochs} epochs")
    ensemble = train_blender_ensemble(library, train_idx, recipe, seed, BLENDER_MEMBERS, log=say)
    kinematic = train_blender_kinematic(library, train_idx, judge_recipe, seed, BLENDER_KINEMATIC_MEMBERS, log=say)
    constrained = blender_networks(encoder, ensembles=(ensemble, kinematic))
    judges = Judges(
        EncoderEnsemble(
            train_judges(library, train_idx, judge_recipe, seed, 5, log=say), architecture=judge_recipe.architecture
        ),
        KinematicJudge(library.dt).fit(movements.velocity, movements.fear),
    )
    setups = {}
    for name, e_des in DIRECTIONS.items():
        say(f"w̃ for '{name}' (e_des = {e_des})")
        table = solution_table(encoder, movements, e_des, cache_dir=None)
        subspace = optimised_subspace(movements, e_des)
        setups[name] = AmplificationSetup(library, train_idx, val_idx, movements, encoder, table, e_des, subspace)
        np.savez_compressed(out / f"w_tilde_{name}.npz", **{k: getattr(table, k) for k in ("values", "rows", "cols")})
        subspace.save(out / f"subspace_{name}.npz")

    episodes = corrector_episodes or (60 if quick else CorrectorConfig.episodes)
    say(f"RL corrector: {episodes} episodes")
    recorded = record_episodes(movements, setups["encode"].table, np.flatnonzero(~movements.fear))
    corrector_config = CorrectorConfig(episodes=episodes, eval_every=min(50, episodes))
    corrector = train(corrector_config, seed, recorded, log=say).network

    fingerprint = library_fingerprint(library)
    meta = {"seed": seed, "library_sha256": fingerprint, "recipe": CHOSEN, "epochs": recipe.epochs}
    torch.save(
        {
            "state_dict": encoder.state_dict(),
            "hidden": config.hidden,
            "dropout": config.dropout,
            "library_sha256": fingerprint,
            "val_fraction": VAL_FRACTION,
            "split_seed": seed,
            "config": asdict(config),
        },
        out / "encoder.pt",
    )
    torch.save(ensemble_checkpoint(ensemble, role="blender", **meta), out / "encoder_ensemble.pt")
    judge_meta = {**meta, "recipe": JUDGE_CHOSEN, "architecture": judge_recipe.architecture}
    torch.save(ensemble_checkpoint(kinematic, role="blender", **judge_meta), out / "encoder_ensemble_kinematic.pt")
    torch.save(ensemble_checkpoint(judges.ensemble.networks, role="judges", **judge_meta), out / "judges.pt")
    torch.save(
        {"state_dict": corrector.state_dict(), "seed": seed, "config": asdict(corrector_config)}, out / "corrector.pt"
    )

    held_out = library.subset(val_idx)
    recorded_decisions = judges.decide(held_out.velocity)
    report: dict[str, Any] = {
        "library": {"n": len(library), **counts, "dt": library.dt, "sha256": fingerprint, **_speed(library)},
        "split": {"seed": seed, "val_fraction": VAL_FRACTION, "train": len(train_idx), "held_out": len(val_idx)},
        "encoder_cv": [{"split_seed": r.split_seed, "accuracy": r.accuracy} for r in folds],
        "encoder_held_out_accuracy": float(
            np.mean((encoder.predict(classifier_inputs(held_out)) > 0.5) == held_out.fear)
        ),
        "judge_accuracy": {name: float(np.mean(d == held_out.fear)) for name, d in recorded_decisions.items()},
        "directions": {},
    }
    for name, setup in setups.items():
        say(f"validation, '{name}': {len(setup.humans) if limit is None else min(limit, len(setup.humans))} movements")
        report["directions"][name] = run_amplification(
            limit=limit,
            e_des=setup.e_des,
            setup=setup,
            judges=judges,
            blender_networks=constrained,
            corrector=corrector,
            step_limit=step_limit,
        )
    report["seconds"] = time.perf_counter() - started
    (out / "report.json").write_text(json.dumps(report, indent=2))
    say(f"done in {report['seconds']:.0f} s: {out / 'report.json'}")
    return report
