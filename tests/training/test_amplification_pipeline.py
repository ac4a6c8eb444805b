"""The whole amplification chain on a user's own library: loading with field mapping, training, validation."""

import json

import numpy as np
import pytest
import torch

from cogblocks.amplification import load_encoder
from cogblocks.amplification.judges import load_ensemble
from cogblocks.amplification.subspace import load_subspace
from cogblocks.cli import main
from cogblocks.data.features import classifier_inputs
from cogblocks.data.loaders import DataFormatError, load_csv, load_npz, save_csv
from cogblocks.data.reach import generate_reach_library
from cogblocks.experiments.amplification_cli import _render_pipeline
from cogblocks.training.judges import BLENDER_KINEMATIC_MEMBERS, BLENDER_MEMBERS
from cogblocks.training.pipeline import DIRECTIONS, load_library, run_pipeline
from cogblocks.training.recipe import CHOSEN

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def library():
    return generate_reach_library(3, n_subjects=3, n_fear=30, n_no_fear=30)


def save_renamed(library, path, *, with_dt):
    """An npz archive as a partner might hold it: the label under another name, maybe no sampling step."""
    arrays = {
        "velocity": library.velocity,
        "position": library.position,
        "length": library.length,
        "condition": library.fear,
        "subject": library.subject,
        "target": library.target,
    }
    if with_dt:
        arrays["dt"] = np.float64(library.dt)
    np.savez(path, **arrays)


def test_missing_fields_say_how_to_map_them(library, tmp_path, capsys):
    path = tmp_path / "mine.npz"
    save_renamed(library, path, with_dt=False)
    with pytest.raises(DataFormatError, match=r"missing key\(s\) 'fear', 'dt'.*--label-field NAME.*--dt SECONDS"):
        load_npz(path)
    assert main(["run", "amplification", "--library", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "'fear'" in err and "--label-field" in err and "--dt" in err
    mapped = load_library(path, label_field="condition", dt=0.02)
    assert mapped.dt == 0.02 and np.array_equal(mapped.fear, library.fear)
    csv = tmp_path / "mine.csv"
    save_csv(library, csv)
    csv.write_text(csv.read_text().replace("fear", "afraid", 1))
    with pytest.raises(DataFormatError, match=r"missing column\(s\) 'fear'.*--label-field"):
        load_csv(csv)
    assert np.array_equal(load_library(csv, label_field="afraid").fear, library.fear)
    with pytest.raises(ValueError, match="unknown library format"):
        load_library(tmp_path / "mine.txt")
    assert main(["run", "amplification", "--library", str(path)]) == 2
    assert "--out" in capsys.readouterr().err


def test_run_pipeline_on_a_renamed_library(library, tmp_path):
    path = tmp_path / "mine.npz"
    save_renamed(library, path, with_dt=True)
    out = tmp_path / "out"
    lines = []
    report = run_pipeline(
        path, out, seed=2, label_field="condition", limit=1, encoder_epochs=2, corrector_episodes=2, log=lines.append
    )
    assert any("cross-validation" in line for line in lines) and any("judge 5/5" in line for line in lines)
    for name in ("encoder.pt", "encoder_ensemble.pt", "encoder_ensemble_kinematic.pt", "judges.pt", "corrector.pt",
                 "report.json"):  # fmt: skip
        assert (out / name).stat().st_size > 0
    assert json.loads((out / "report.json").read_text()) == json.loads(json.dumps(report))
    train, val = library.split(0.3, 2)
    assert report["split"] == {"seed": 2, "val_fraction": 0.3, "train": len(train), "held_out": len(val)}
    assert len(report["encoder_cv"]) == 5
    text = _render_pipeline(report)  # what `run amplification --library` prints without --json
    assert text.startswith(f"library of {len(library)} movements") and "held-out movements, " in text
    with pytest.raises(json.JSONDecodeError):
        json.loads(text)
    encoder = load_encoder(out / "encoder.pt")
    held_out = library.subset(val)
    accuracy = np.mean((encoder.predict(classifier_inputs(held_out)) > 0.5) == held_out.fear)
    assert report["encoder_held_out_accuracy"] == pytest.approx(accuracy)
    blender = load_ensemble(out / "encoder_ensemble.pt")
    assert len(load_ensemble(out / "judges.pt")) == 5 and len(blender) == BLENDER_MEMBERS
    assert blender[0].checkpoint["recipe"] == CHOSEN
    kinematic = load_ensemble(out / "encoder_ensemble_kinematic.pt")
    assert len(kinematic) == BLENDER_KINEMATIC_MEMBERS and all(n.hidden.in_features == 66 for n in kinematic)
    # the optimised blender's subspaces: the PCA of the training part's movements of each direction's class
    movements = library.subset(train)
    for name, e_des in DIRECTIONS.items():
        subspace = load_subspace(out / f"subspace_{name}.npz")
        assert subspace.e_des == e_des
        np.testing.assert_allclose(subspace.mean, classifier_inputs(movements)[movements.fear == bool(e_des)].mean(0))
    table = np.load(out / "w_tilde_remove.npz")
    assert set(table["rows"]) <= set(np.flatnonzero(library.subset(train).fear))  # e_des = 0: fear rows
    assert set(report["directions"]) == set(DIRECTIONS)
    for direction in report["directions"].values():
        assert set(direction) == {"blend", "blend_rl", "optimised"}
        for row in direction.values():
            assert row["n"] == 1 and row["encoded_independent"] == row["judges"]["ensemble"]
            assert set(row["judges"]) == {"ensemble", "kinematic"}


def test_mat_label_under_another_name(tmp_path):
    import scipy.io

    rng = np.random.default_rng(0)
    trials = [("ASSOCIATION", 3, 1), ("EXTINCTION", 1, 0), ("BASELINE", 1, 1)]
    array = np.empty((1, 3), dtype=[(f, object) for f in ("Vxyzf", "Fear", "Phase", "Subphase")])
    for k, (phase, subphase, label) in enumerate(trials):
        array[0, k]["Vxyzf"] = rng.normal(size=(20, 3))
        array[0, k]["Fear"] = label
        array[0, k]["Phase"] = phase
        array[0, k]["Subphase"] = subphase
    path = tmp_path / "mine.mat"
    scipy.io.savemat(path, {"VelocityData": {"P01": array}})
    with pytest.raises(DataFormatError, match=r"missing field 'Condition' \(fields: Vxyzf, Fear.*--label-field NAME"):
        load_library(path)
    mapped = load_library(path, label_field="Fear", dt=0.005)
    # baseline trials are no fear whatever their label; the others keep it
    assert mapped.fear.tolist() == [True, False, False] and mapped.dt == 0.005


def test_load_library_converts_the_files_length_unit(library, tmp_path):
    from cogblocks.data.reach import ReachLibrary

    in_cm = ReachLibrary(
        library.velocity / 10, library.position / 10, library.length, library.fear, library.subject,
        library.target, library.dt,
    )  # fmt: skip
    save_csv(in_cm, tmp_path / "cm.csv")
    loaded = load_library(tmp_path / "cm.csv", unit="cm", max_len=library.max_len)
    np.testing.assert_allclose(loaded.position, library.position, rtol=1e-12, atol=1e-9)
    with pytest.raises(ValueError, match="unit 'px' is not a length unit"):
        load_library(tmp_path / "cm.csv", unit="px")


def test_unit_of_a_library_file(library, tmp_path, capsys):
    """``--unit`` reads the file's lengths in that unit: a file in cm trains on speeds ten times its numbers."""
    assert main(["run", "amplification", "--unit", "m"]) == 2
    assert "--unit applies to --library FILE only" in capsys.readouterr().err
    path = tmp_path / "in_cm.csv"
    save_csv(library, path)
    report = run_pipeline(path, tmp_path / "out", unit="cm", limit=1, encoder_epochs=1, corrector_episodes=1, log=None)
    moving = np.arange(library.velocity.shape[1]) < library.length[:, None]
    speeds = 10.0 * np.linalg.norm(library.velocity, axis=-1)[moving]  # cm/s as mm/s
    assert report["library"]["speed_rms_mm_s"] == pytest.approx(np.sqrt(np.mean(speeds**2)), rel=1e-9)
