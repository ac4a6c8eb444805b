"""library_from_recordings: a reach library from labelled C3D trials written with ezc3d."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("ezc3d")

from cogblocks.data.c3d import write_c3d  # noqa: E402
from cogblocks.data.loaders import DataFormatError  # noqa: E402
from cogblocks.data.reach import generate_reach_library  # noqa: E402
from cogblocks.data.reach_recordings import ReachTrial, library_from_recordings  # noqa: E402


def _trials(tmp_path, library, unit="m", per_mm=1e-3):
    trials = []
    for i in range(len(library)):
        n = int(library.length[i])
        path = tmp_path / f"trial{i}.c3d"
        write_c3d(path, library.position[i, :n, None] * per_mm, ["RWRA"], 1 / library.dt, unit=unit)
        trials.append(ReachTrial(path, fear=bool(library.fear[i]), subject=int(library.subject[i])))
    return trials


def test_a_library_from_c3d_trials_keeps_positions_labels_and_the_velocity(tmp_path):
    library = generate_reach_library(seed=0, n_subjects=2, n_fear=3, n_no_fear=3)
    built = library_from_recordings(_trials(tmp_path, library), "RWRA")
    np.testing.assert_array_equal(built.length, library.length)
    np.testing.assert_array_equal(built.fear, library.fear)
    np.testing.assert_array_equal(built.subject, library.subject)
    assert (built.target == -1).all()
    for i in range(len(library)):
        n = int(library.length[i])
        np.testing.assert_allclose(built.position[i, :n], library.position[i, :n], atol=2e-4)  # float32 in the file
        np.testing.assert_allclose(built.velocity[i, :n], np.gradient(built.position[i, :n], library.dt, axis=0))
        np.testing.assert_array_equal(built.velocity[i, n:], 0.0)


def test_a_trial_with_a_gap_or_too_long_is_refused_naming_the_file(tmp_path):
    library = generate_reach_library(seed=1, n_subjects=1, n_fear=1, n_no_fear=1)
    n = int(library.length[0])
    p = library.position[0, :n].copy()
    p[10:14] = np.nan
    write_c3d(tmp_path / "gap.c3d", p[:, None], ["RWRA"], 100)
    with pytest.raises(DataFormatError, match=r"gap\.c3d: marker 'RWRA' is lost on 4 tick\(s\) from 0\.100 s"):
        library_from_recordings([ReachTrial(tmp_path / "gap.c3d", fear=True)], "RWRA")
    write_c3d(tmp_path / "long.c3d", np.zeros((300, 1, 3)), ["RWRA"], 100)
    with pytest.raises(DataFormatError, match=r"long\.c3d: 300 samples at dt=0\.01 s, expected 2\.\.max_len=200"):
        library_from_recordings([ReachTrial(tmp_path / "long.c3d", fear=False)], "RWRA")
