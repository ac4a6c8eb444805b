"""Loaders of reach-to-grasp libraries: npz, CSV and the MATLAB layout of the real data set."""

import pickle
import re
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from cogblocks.data.loaders import (
    CSV_COLUMNS,
    DataFormatError,
    load_csv,
    load_npz,
    load_velocity_data_mat,
    save_csv,
    save_npz,
)
from cogblocks.data.reach import ReachLibrary, generate_reach_library

FIELDS = ("velocity", "position", "length", "fear", "subject", "target")


@pytest.fixture(scope="module")
def library() -> ReachLibrary:
    return generate_reach_library(0)


@pytest.fixture(scope="module")
def small(library) -> ReachLibrary:
    return library.subset(np.arange(0, len(library), 12))


def assert_same_library(actual: ReachLibrary, expected: ReachLibrary) -> None:
    for field in FIELDS:
        np.testing.assert_array_equal(getattr(actual, field), getattr(expected, field), err_msg=field)
    assert actual.dt == expected.dt


def assert_format_error(loader, path: Path, fragment: str) -> None:
    with pytest.raises(DataFormatError, match=re.escape(fragment)) as info:
        loader(path)
    assert str(path) in str(info.value)


# --- npz -----------------------------------------------------------------------------------------------------


def test_npz_round_trip_is_exact(library, tmp_path):
    path = tmp_path / "library.bin"  # written exactly at the given path, no suffix added
    save_npz(library, path)
    assert path.is_file()
    assert_same_library(load_npz(path), library)


def write_npz(path: Path, library: ReachLibrary, **changes) -> Path:
    arrays = {field: getattr(library, field) for field in FIELDS} | {"dt": np.float64(library.dt)}
    arrays.update(changes)
    np.savez(path, **{key: value for key, value in arrays.items() if value is not None})
    return path


@pytest.mark.parametrize(
    ("changes", "fragment"),
    [
        ({"target": None}, "missing key(s) 'target'"),
        ({"velocity": np.zeros((25, 200))}, "velocity must have shape (n, max_len, 3)"),
        ({"length": np.zeros(3, dtype=int)}, "length must have shape (39,)"),
        ({"subject": np.array(["a"] * 39)}, "key 'subject' is not numeric"),
        ({"dt": np.array([0.01, 0.01])}, "key 'dt' must be a scalar"),
    ],
)
def test_malformed_npz(small, tmp_path, changes, fragment):
    assert_format_error(load_npz, write_npz(tmp_path / "bad.npz", small, **changes), fragment)


def test_npz_with_nan_velocity(small, tmp_path):
    velocity = small.velocity.copy()
    velocity[3, 10, 1] = np.nan
    assert_format_error(load_npz, write_npz(tmp_path / "nan.npz", small, velocity=velocity), "velocity contains NaN")


def test_npz_with_object_array(small, tmp_path):
    path = write_npz(tmp_path / "objects.npz", small, fear=np.array([None] * 39, dtype=object))
    assert_format_error(load_npz, path, "key 'fear' is unreadable")


def test_pickled_data_is_refused_without_suggesting_allow_pickle(small, tmp_path):
    """numpy's own message advises ``allow_pickle=True``, which would let the file run code: never repeated."""
    objects = write_npz(tmp_path / "objects.npz", small, fear=np.array([None] * 39, dtype=object))
    pickled = tmp_path / "pickled.npz"
    pickled.write_bytes(pickle.dumps({"velocity": [1.0, 2.0]}))
    for path, fragment in ((objects, "key 'fear' is unreadable"), (pickled, "not an npz archive")):
        with pytest.raises(DataFormatError, match=re.escape(fragment)) as info:
            load_npz(path)
        message = str(info.value)
        assert str(path) in message and "pickled Python objects, which are never loaded" in message
        assert "allow_pickle" not in message and "pickle.load" not in message


def test_files_that_are_not_npz_archives(tmp_path):
    text = tmp_path / "notes.npz"
    text.write_text("not an archive\n")
    assert_format_error(load_npz, text, "not an npz archive")
    single = tmp_path / "single.npy"
    np.save(single, np.zeros(3))
    assert_format_error(load_npz, single, "not an npz archive (a single .npy array)")


# --- CSV -------------------------------------------------------------------------------------------------------


def test_csv_round_trip_is_exact(small, tmp_path):
    path = tmp_path / "library.csv"
    save_csv(small, path)
    lines = path.read_text().splitlines()
    assert lines[0] == ",".join(CSV_COLUMNS)
    assert len(lines) == 1 + small.length.sum()
    assert_same_library(load_csv(path), small)


def test_csv_accepts_shuffled_rows_reordered_and_extra_columns(small, tmp_path):
    path = tmp_path / "library.csv"
    save_csv(small, path)
    header, *rows = path.read_text().splitlines()
    cells = [row.split(",") for row in rows]
    order = [10, 0, 4, 2, 1, 3, 5, 6, 7, 8, 9]
    shuffled = np.random.default_rng(0).permutation(len(rows))
    lines = [",".join([header.split(",")[k] for k in order] + ["note"])]
    lines += [",".join([cells[r][k] for k in order] + ["x"]) for r in shuffled]
    path.write_text("\n".join(lines) + "\n")
    # Movements come in the order of their first row in the file.
    movement_column = np.array([int(cells[r][0]) for r in shuffled])
    first_seen = movement_column[np.sort(np.unique(movement_column, return_index=True)[1])]
    assert_same_library(load_csv(path), small.subset(first_seen))


def test_csv_with_a_byte_order_mark(small, tmp_path):
    """Spreadsheet programs save "CSV UTF-8" with a BOM before the first column name."""
    path = tmp_path / "excel.csv"
    save_csv(small, path)
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
    assert_same_library(load_csv(path), small)


def test_csv_movements_with_shared_ids_in_any_order(small, tmp_path):
    """Interleaved movements are grouped by id, each sorted by t, checked and kept in order of first row."""
    path = tmp_path / "interleaved.csv"
    save_csv(small, path)
    header, *rows = path.read_text().splitlines()
    movement = np.array([int(row.split(",")[0]) for row in rows])
    t = np.array([int(row.split(",")[4]) for row in rows])
    # movements interleaved sample by sample, each in reverse t order
    order = sorted(range(len(rows)), key=lambda r: (-t[r], movement[r]))
    path.write_text("\n".join([header] + [rows[r] for r in order]) + "\n")
    # the first row of each movement is its last sample: longest movements first
    expected = sorted(range(len(small)), key=lambda m: (-small.length[m], m))
    assert len(set(small.length[expected[:5]])) > 1  # the order is not the library's
    assert_same_library(load_csv(path), small.subset(np.array(expected)))


def write_csv(path: Path, small: ReachLibrary, edit) -> Path:
    """Write ``small`` as CSV, then apply ``edit`` to its list of lines."""
    save_csv(small, path)
    lines = path.read_text().splitlines()
    path.write_text("\n".join(edit(lines)) + "\n")
    return path


def replace_cell(line: str, column: str, value: str) -> str:
    cells = line.split(",")
    cells[CSV_COLUMNS.index(column)] = value
    return ",".join(cells)


@pytest.mark.parametrize(
    ("edit", "fragment"),
    [
        (lambda lines: [lines[0].replace(",vy", ",vq")] + lines[1:], "missing column(s) 'vy'"),
        (lambda lines: [lines[0] + ",vx"] + [line + ",0" for line in lines[1:]], "duplicated column(s) 'vx'"),
        (lambda lines: lines[:1], "no data rows after the header"),
        (lambda lines: lines[:5] + [replace_cell(lines[5], "px", "abc")] + lines[6:], "line 6, column 'px': 'abc'"),
        (
            lambda lines: lines[:3] + [replace_cell(lines[3], "vz", "nan")] + lines[4:],
            "line 4, column 'vz': value is NaN",
        ),
        (lambda lines: lines[:4] + [lines[4] + ",1"] + lines[5:], "line 5: 12 fields, the header has 11"),
        (lambda lines: lines[:2] + lines[3:], "movement 0: t must be 0.."),
        (lambda lines: lines[:2] + [replace_cell(lines[2], "fear", "1")] + lines[3:], "'fear' changes within"),
        (
            lambda lines: lines[:2] + [replace_cell(lines[2], "subject", "0.5")] + lines[3:],
            "column 'subject': expected",
        ),
        (lambda lines: lines[:2] + [replace_cell(lines[2], "target", "3")] + lines[3:], "'target' changes within"),
    ],
)
def test_malformed_csv(small, tmp_path, edit, fragment):
    assert_format_error(load_csv, write_csv(tmp_path / "bad.csv", small, edit), fragment)


def test_csv_invalid_label_and_too_long_movement(small, tmp_path):
    def every_target_is_three(lines):
        return lines[:1] + [replace_cell(line, "target", "3") for line in lines[1:]]

    path = write_csv(tmp_path / "targets.csv", small, every_target_is_three)
    assert_format_error(load_csv, path, "target must be 0, 1 or -1")
    path = write_csv(tmp_path / "long.csv", small, lambda lines: lines)
    with pytest.raises(DataFormatError, match=r"movement 0: \d+ samples, more than max_len=50"):
        load_csv(path, max_len=50)


def test_csv_binary_file(tmp_path):
    path = tmp_path / "binary.csv"
    path.write_bytes(b"\x89PNG\r\n\x1a\n\xff\xfe\x00")
    assert_format_error(load_csv, path, "not a CSV text file")


# --- MATLAB layout --------------------------------------------------------------------------------------------


def trial(phase: str, subphase: int, condition: int, velocity, number: int) -> dict:
    return {
        "Vxyzf": velocity,
        "Condition": condition,
        "Phase": phase,
        "Subphase": subphase,
        "Movement_Time": 0.01 * len(velocity),
        "Trial_Number": number,
    }


def struct_array(trials: list[dict]) -> np.ndarray:
    """A 1 x N MATLAB struct array of trials, as scipy.io.savemat writes one."""
    array = np.empty((1, len(trials)), dtype=[(field, object) for field in trials[0]])
    for k, fields in enumerate(trials):
        for field, value in fields.items():
            array[0, k][field] = value
    return array


def cell_array(trials: list[dict]) -> np.ndarray:
    array = np.empty((1, len(trials)), dtype=object)
    for k, fields in enumerate(trials):
        array[0, k] = fields
    return array


def write_mat(path: Path, participants: dict) -> Path:
    scipy.io.savemat(path, {"VelocityData": participants})
    return path


def velocity_of(rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.normal(0.0, 300.0, (n, 3))


def test_mat_selection_labels_and_integration(tmp_path):
    rng = np.random.default_rng(0)
    v = [velocity_of(rng, n) for n in (50, 40, 60, 45, 70, 55, 65, 30, 35)]
    participants = {
        "P01": struct_array(
            [
                trial("BASELINE", 1, 1, v[0], 1),  # kept as no fear whatever the condition
                trial("ASSOCIATION", 1, 1, v[1], 2),  # dropped
                trial("ASSOCIATION", 2, 0, v[2], 3),  # dropped
                trial("ASSOCIATION", 3, 1, v[3], 4),  # fear
                trial("ASSOCIATION", 3, 0, v[4], 5),  # no fear
                trial("EXTINCTION", 1, 1, v[5], 6),  # fear
                trial("EXTINCTION", 2, 1, v[6], 7),  # dropped
            ]
        ),
        "P02": struct_array([trial("extinction", 1, 0, v[7], 1)]),  # a single trial, lower-case phase
        "P03": cell_array([trial("Baseline", 2, 0, v[8], 1)]),  # trials stored as a cell array
    }
    library = load_velocity_data_mat(write_mat(tmp_path / "data.mat", participants))
    kept = [0, 3, 4, 5, 7, 8]
    assert len(library) == len(kept)
    np.testing.assert_array_equal(library.fear, [False, True, False, True, False, False])
    np.testing.assert_array_equal(library.subject, [0, 0, 0, 0, 1, 2])
    np.testing.assert_array_equal(library.target, -1)
    np.testing.assert_array_equal(library.length, [len(v[k]) for k in kept])
    for i, k in enumerate(kept):
        n = len(v[k])
        np.testing.assert_array_equal(library.velocity[i, :n], v[k])
        assert np.all(library.velocity[i, n:] == 0.0)
        np.testing.assert_array_equal(library.position[i, 0], 0.0)  # integrated from the origin
        np.testing.assert_allclose(np.diff(library.position[i, :n], axis=0) / 0.01, v[k][:-1], atol=1e-9)
        assert np.all(library.position[i, n:] == library.position[i, n - 1])


def test_mat_round_trip_of_a_generated_library(small, tmp_path):
    participants = {}
    for s in np.unique(small.subject):
        rows = np.flatnonzero(small.subject == s)
        participants[f"P{s:02d}"] = struct_array(
            [trial("ASSOCIATION", 3, int(small.fear[i]), small.restricted(i)[1], int(i)) for i in rows]
        )
    loaded = load_velocity_data_mat(write_mat(tmp_path / "generated.mat", participants))
    for field in ("velocity", "length", "fear", "subject"):
        np.testing.assert_array_equal(getattr(loaded, field), getattr(small, field), err_msg=field)
    # Positions differ only by the start position, which the file does not hold.
    offsets = small.position - small.position[:, :1]
    np.testing.assert_allclose(loaded.position, offsets, atol=1e-9)


def one_participant(tmp_path: Path, *trials: dict) -> Path:
    return write_mat(tmp_path / "bad.mat", {"P07": struct_array(list(trials))})


GOOD_VELOCITY = np.ones((20, 3))


@pytest.mark.parametrize(
    ("trials", "fragment"),
    [
        ([trial("ASSOCIATION", 3, 1, np.ones((20, 2)), 4)], "participant 'P07', trial 4: Vxyzf must have shape (T, 3)"),
        ([trial("ASSOCIATION", 3, 1, "fast", 4)], "trial 4: Vxyzf must be numeric"),
        ([trial("BASELINE", 1, 0, np.full((20, 3), np.nan), 2)], "trial 2: Vxyzf contains NaN"),
        ([trial("RECALL", 1, 0, GOOD_VELOCITY, 9)], "trial 9: unknown Phase 'RECALL'"),
        ([trial("EXTINCTION", 1, 2, GOOD_VELOCITY, 3)], "trial 3: Condition must be 0 (no fear) or 1 (fear), got 2"),
        (
            [trial("EXTINCTION", 1, 0, np.ones((201, 3)), 5)],
            "participant 'P07', trial 5: 201 samples, more than max_len",
        ),
        ([trial("ASSOCIATION", 1, 1, GOOD_VELOCITY, 1)], "no trial is baseline, association subphase 3"),
    ],
)
def test_malformed_mat_trials(tmp_path, trials, fragment):
    assert_format_error(load_velocity_data_mat, one_participant(tmp_path, *trials), fragment)


def test_mat_trial_without_a_field(tmp_path):
    fields = trial("BASELINE", 1, 0, GOOD_VELOCITY, 1)
    del fields["Vxyzf"]
    assert_format_error(load_velocity_data_mat, one_participant(tmp_path, fields), "trial 1: missing field 'Vxyzf'")


def test_mat_optional_fields_can_be_missing(tmp_path):
    minimal = {"Vxyzf": GOOD_VELOCITY, "Condition": 0, "Phase": "BASELINE", "Subphase": 1}
    library = load_velocity_data_mat(one_participant(tmp_path, minimal, minimal))
    assert len(library) == 2
    unnamed = {**minimal, "Phase": "HABITUATION"}
    assert_format_error(
        load_velocity_data_mat, one_participant(tmp_path, minimal, unnamed), "trial #2 (in file order): unknown Phase"
    )


def test_mat_file_level_errors(tmp_path):
    path = tmp_path / "other.mat"
    scipy.io.savemat(path, {"Kinematics": np.zeros(3)})
    assert_format_error(load_velocity_data_mat, path, "missing variable 'VelocityData'")
    scipy.io.savemat(path, {"VelocityData": np.zeros(3)})
    assert_format_error(load_velocity_data_mat, path, "'VelocityData' must be a struct")
    scipy.io.savemat(path, {"VelocityData": {"P01": np.zeros(3)}})
    assert_format_error(load_velocity_data_mat, path, "participant 'P01' must hold a struct array of trials")
    text = tmp_path / "text.mat"
    text.write_text("this is not a MATLAB file, only text that is long enough to have a header\n" * 3)
    assert_format_error(load_velocity_data_mat, text, "not a readable MATLAB file")


# --- missing and empty files -----------------------------------------------------------------------------------


@pytest.mark.parametrize("loader", [load_npz, load_csv, load_velocity_data_mat])
def test_missing_and_empty_files(tmp_path, loader):
    missing = tmp_path / "nowhere" / "data.file"
    with pytest.raises(FileNotFoundError, match=re.escape(str(missing))):
        loader(missing)
    empty = tmp_path / "empty.file"
    empty.write_bytes(b"")
    assert_format_error(loader, empty, "empty file")


@pytest.mark.parametrize("loader", [load_npz, load_csv, load_velocity_data_mat])
def test_a_directory_is_reported_as_a_directory(tmp_path, loader):
    folder = tmp_path / "data.csv"
    folder.mkdir()
    with pytest.raises(IsADirectoryError, match="Is a directory, expected a file") as info:
        loader(folder)
    assert info.value.filename == str(folder)


# --- length units ----------------------------------------------------------------------------------


@pytest.mark.parametrize(("unit", "per_mm"), [("m", 1e-3), ("cm", 0.1), ("mm", 1.0)])
def test_every_loader_converts_the_files_length_unit_to_mm(tmp_path, unit, per_mm):
    library = generate_reach_library(seed=0, n_subjects=2, n_fear=3, n_no_fear=3)
    in_unit = ReachLibrary(
        library.velocity * per_mm,
        library.position * per_mm,
        library.length,
        library.fear,
        library.subject,
        library.target,
        library.dt,
    )
    save_npz(in_unit, tmp_path / "lib.npz")
    save_csv(in_unit, tmp_path / "lib.csv")
    for loaded in (
        load_npz(tmp_path / "lib.npz", unit=unit),
        load_csv(tmp_path / "lib.csv", max_len=library.max_len, unit=unit),
    ):
        np.testing.assert_allclose(loaded.position, library.position, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(loaded.velocity, library.velocity, rtol=1e-12, atol=1e-9)
    v = velocity_of(np.random.default_rng(1), 30)
    mat = write_mat(tmp_path / "lib.mat", {"P01": struct_array([trial("BASELINE", 1, 0, v * per_mm, 1)])})
    loaded = load_velocity_data_mat(mat, unit=unit)
    np.testing.assert_allclose(loaded.velocity[0, :30], v, rtol=1e-12, atol=1e-9)


def test_an_npz_archive_may_declare_its_unit(tmp_path):
    library = generate_reach_library(seed=0, n_subjects=2, n_fear=3, n_no_fear=3)
    fields = {k: getattr(library, k) for k in ("length", "fear", "subject", "target")}
    np.savez(
        tmp_path / "m.npz",
        velocity=library.velocity / 1000,
        position=library.position / 1000,
        dt=library.dt,
        unit="m",
        **fields,
    )
    np.testing.assert_allclose(load_npz(tmp_path / "m.npz").position, library.position, rtol=1e-12)
    np.savez(
        tmp_path / "deg.npz", velocity=library.velocity, position=library.position, dt=library.dt, unit="deg", **fields
    )
    with pytest.raises(DataFormatError, match=r"deg\.npz: unit: unit 'deg' is not a length unit"):
        load_npz(tmp_path / "deg.npz")


def test_a_unit_that_is_not_a_length_is_refused_by_every_loader_naming_it(tmp_path):
    library = generate_reach_library(seed=0, n_subjects=2, n_fear=3, n_no_fear=3)
    save_npz(library, tmp_path / "lib.npz")
    save_csv(library, tmp_path / "lib.csv")
    with pytest.raises(ValueError, match=r"load_npz: unit: unit 'rad' is not a length unit \(allowed: m, cm, mm\)"):
        load_npz(tmp_path / "lib.npz", unit="rad")
    with pytest.raises(ValueError, match=r"load_csv: unit: unit 'mm/s' is not a length unit"):
        load_csv(tmp_path / "lib.csv", unit="mm/s")
    with pytest.raises(ValueError, match=r"load_velocity_data_mat: unit: unit 'inch' is not a length unit"):
        load_velocity_data_mat(tmp_path / "lib.csv", unit="inch")
