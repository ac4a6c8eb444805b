"""Reading and writing reach-to-grasp libraries: the MATLAB layout of the real data, npz and CSV.

Every reader returns a :class:`~cogblocks.data.reach.ReachLibrary` padded to ``max_len`` samples
(velocity with zeros, position by holding the last position). A malformed file raises
:class:`DataFormatError` whose message starts with the file name and says what is wrong; a missing
file raises :class:`FileNotFoundError` and a directory :class:`IsADirectoryError`, both naming the
path. Pickled Python objects are never loaded (loading them can run arbitrary code).

Every reader takes the file's length unit (``unit``: m, cm or mm; velocities in that unit per
second) and converts to the library's mm and mm/s; a unit that is not a length is refused, named.
"""

from __future__ import annotations

import csv
import errno
import os
import zipfile
from array import array as flat_array
from pathlib import Path
from typing import Any

import numpy as np
import scipy.io

from cogblocks.data.reach import ReachLibrary
from cogblocks.data.units import to_mm

__all__ = [
    "CSV_COLUMNS",
    "DataFormatError",
    "load_csv",
    "load_npz",
    "load_velocity_data_mat",
    "save_csv",
    "save_npz",
]

CSV_COLUMNS = ("movement", "subject", "fear", "target", "t", "px", "py", "pz", "vx", "vy", "vz")
_NPZ_KEYS = ("velocity", "position", "length", "fear", "subject", "target", "dt")
_PHASES = ("BASELINE", "ASSOCIATION", "EXTINCTION")
# The conditioned trials the prototype keeps with their Condition label; other subphases are dropped.
_KEPT_SUBPHASE = {"ASSOCIATION": 3, "EXTINCTION": 1}


_LABEL_HINT = "; if the fear label has another name, map it with label_field=NAME (command line: --label-field NAME)"
_DT_HINT = "; give the sampling step with dt=SECONDS (command line: --dt SECONDS)"


class DataFormatError(ValueError):
    """A data file exists but its content does not follow the expected format."""


PathLike = str | os.PathLike


def _existing_file(path: PathLike) -> Path:
    """``path`` as a Path, after checking that it is a non-empty file."""
    file = Path(path)
    if file.is_dir():
        raise IsADirectoryError(errno.EISDIR, f"{os.strerror(errno.EISDIR)}, expected a file", str(path))
    if not file.is_file():
        raise FileNotFoundError(errno.ENOENT, os.strerror(errno.ENOENT), str(path))
    if file.stat().st_size == 0:
        raise DataFormatError(f"{file}: empty file")
    return file


def _unreadable(error: Exception) -> str:
    """Why numpy refused an array, without numpy's advice to load pickled data (unsafe)."""
    if "pickle" in str(error).lower():
        return "it holds pickled Python objects, which are never loaded: loading them can run arbitrary code"
    return str(error)


def _is_real(dtype: np.dtype) -> bool:
    """Booleans, integers and real floats (not complex, text or objects)."""
    return np.issubdtype(dtype, np.bool_) or np.issubdtype(dtype, np.integer) or np.issubdtype(dtype, np.floating)


def _library_from_movements(
    file: Path,
    velocities: list[np.ndarray],
    positions: list[np.ndarray],
    labels: dict[str, list[int]],
    max_len: int,
    dt: float,
    scale: float = 1.0,
) -> ReachLibrary:
    """Pad movements of their own lengths (velocity with zeros, position holding its last value), times ``scale``."""
    n = len(velocities)
    velocity = np.zeros((n, max_len, 3))
    position = np.zeros((n, max_len, 3))
    for i, (v, p) in enumerate(zip(velocities, positions, strict=True)):
        velocity[i, : len(v)] = v
        position[i, : len(p)] = p
        position[i, len(p) :] = p[-1]
    try:
        return ReachLibrary(
            velocity=velocity * scale,
            position=position * scale,
            length=np.array([len(v) for v in velocities], dtype=np.int64),
            dt=dt,
            **{name: np.array(values, dtype=np.int64) for name, values in labels.items()},
        )
    except ValueError as error:
        raise DataFormatError(f"{file}: {error}") from error


# --- MATLAB layout of the real data set ------------------------------------------------------------


def load_velocity_data_mat(
    path: PathLike, max_len: int = 200, dt: float = 0.01, *, label_field: str = "Condition", unit: str = "mm"
) -> ReachLibrary:
    """Load the real data set's MATLAB file (struct ``VelocityData``, one field per participant).

    Each participant field holds that participant's trials, as a struct array (or a cell array of
    structs) with the fields ``Vxyzf`` (T x 3 velocity, mm/s), ``Condition`` (1 fear, 0 no fear),
    ``Phase`` ('BASELINE', 'ASSOCIATION' or 'EXTINCTION', any case), ``Subphase``, and optionally
    ``Trial_Number`` (used to name a trial in error messages) and ``Movement_Time`` (ignored: a
    trial's length is the number of rows of ``Vxyzf``).

    Trials are selected as in the appendix paper's prototype: baseline trials are kept as no fear
    whatever their ``Condition``; association trials of subphase 3 and extinction trials of
    subphase 1 are kept with their ``Condition`` label; all other trials are dropped.

    The file holds no positions: position is reconstructed by integrating the velocity from the
    origin, ``p(0) = 0``, ``p(t+1) = p(t) + dt v(t)``, so eq. (1) holds to rounding error. The file
    does not say which cube was reached either, so ``target`` is -1 (unknown). ``subject`` is the
    index of the participant field in the order the file stores them.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.mat`` file (MATLAB v5 to v7.2; v7.3 HDF5 files are not supported by scipy).
    max_len : int
        Padded number of samples. A kept trial longer than this raises :class:`DataFormatError`
        naming the participant and the trial, rather than being truncated silently.
    dt : float
        Sampling time in seconds (the motion capture ran at 100 Hz).
    label_field : str
        The trial field holding the fear label (``Condition``).
    unit : {"mm", "cm", "m"}
        Length unit of ``Vxyzf`` (velocities in ``unit``/s), converted to mm/s.

    Returns
    -------
    ReachLibrary

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    DataFormatError
        If the file is not a MATLAB file or does not follow the layout above.
    """
    file = _existing_file(path)
    scale = to_mm(unit, "load_velocity_data_mat: unit")
    try:
        content = scipy.io.loadmat(file, squeeze_me=True, struct_as_record=False)
    except (ValueError, TypeError, OSError, NotImplementedError) as error:
        raise DataFormatError(f"{file}: not a readable MATLAB file ({error})") from error
    if "VelocityData" not in content:
        raise DataFormatError(f"{file}: missing variable 'VelocityData'")
    data = content["VelocityData"]
    if not isinstance(data, scipy.io.matlab.mat_struct):
        raise DataFormatError(f"{file}: 'VelocityData' must be a struct with one field per participant")

    velocities: list[np.ndarray] = []
    labels: dict[str, list[int]] = {"fear": [], "subject": [], "target": []}
    for subject, participant in enumerate(data._fieldnames):
        for position_in_file, trial in enumerate(_participant_trials(file, participant, getattr(data, participant))):
            name = f"{file}: participant '{participant}', {_trial_label(trial, position_in_file)}"
            fear = _trial_fear_label(name, trial, label_field)
            if fear is None:
                continue
            velocity = _trial_velocity(name, trial)
            if len(velocity) > max_len:
                raise DataFormatError(f"{name}: {len(velocity)} samples, more than max_len={max_len}")
            velocities.append(velocity)
            labels["fear"].append(int(fear))
            labels["subject"].append(subject)
            labels["target"].append(-1)
    if not velocities:
        raise DataFormatError(f"{file}: no trial is baseline, association subphase 3 or extinction subphase 1")
    positions = [np.concatenate([np.zeros((1, 3)), np.cumsum(v[:-1] * dt, axis=0)]) for v in velocities]
    return _library_from_movements(file, velocities, positions, labels, max_len, dt, scale)


def _participant_trials(file: Path, participant: str, trials: Any) -> list[Any]:
    """The trial structs of one participant, whether stored as a struct array, a cell array or one struct."""
    if isinstance(trials, scipy.io.matlab.mat_struct):
        return [trials]
    if isinstance(trials, np.ndarray) and trials.dtype == object:
        flat = list(trials.reshape(-1))
        if all(isinstance(trial, scipy.io.matlab.mat_struct) for trial in flat):
            return flat
    raise DataFormatError(f"{file}: participant '{participant}' must hold a struct array of trials")


def _trial_label(trial: Any, position_in_file: int) -> str:
    number = getattr(trial, "Trial_Number", None)
    if isinstance(number, (int, float, np.number)) and np.isfinite(number):
        return f"trial {int(number)}"
    return f"trial #{position_in_file + 1} (in file order)"


def _trial_field(name: str, trial: Any, field: str, hint: str = "") -> Any:
    if field not in trial._fieldnames:
        raise DataFormatError(f"{name}: missing field '{field}' (fields: {', '.join(trial._fieldnames)}){hint}")
    return getattr(trial, field)


def _scalar(name: str, field: str, value: Any) -> float:
    array = np.asarray(value)
    if array.size != 1 or not _is_real(array.dtype):
        raise DataFormatError(f"{name}: field '{field}' must be a number, got {value!r}")
    return float(array.reshape(-1)[0])


def _trial_fear_label(name: str, trial: Any, label_field: str = "Condition") -> bool | None:
    """Fear label of a trial, or None when the trial is not used."""
    phase_value = _trial_field(name, trial, "Phase")
    if not isinstance(phase_value, str):
        raise DataFormatError(f"{name}: field 'Phase' must be text, got {phase_value!r}")
    phase = phase_value.strip().upper()
    if phase not in _PHASES:
        raise DataFormatError(f"{name}: unknown Phase '{phase_value}' (expected one of {', '.join(_PHASES)})")
    if phase == "BASELINE":
        return False
    if _scalar(name, "Subphase", _trial_field(name, trial, "Subphase")) != _KEPT_SUBPHASE[phase]:
        return None
    condition = _scalar(name, label_field, _trial_field(name, trial, label_field, _LABEL_HINT))
    if condition not in (0.0, 1.0):
        raise DataFormatError(f"{name}: {label_field} must be 0 (no fear) or 1 (fear), got {condition:g}")
    return condition == 1.0


def _trial_velocity(name: str, trial: Any) -> np.ndarray:
    raw = _trial_field(name, trial, "Vxyzf")
    velocity = np.asarray(raw)
    if not _is_real(velocity.dtype):
        raise DataFormatError(f"{name}: Vxyzf must be numeric, got dtype {velocity.dtype}")
    if velocity.shape == (3,):  # squeeze_me turns a single 1 x 3 sample into a vector
        velocity = velocity.reshape(1, 3)
    if velocity.ndim != 2 or velocity.shape[1] != 3 or velocity.shape[0] < 1:
        raise DataFormatError(f"{name}: Vxyzf must have shape (T, 3) with T >= 1, got {velocity.shape}")
    if not np.all(np.isfinite(velocity)):
        raise DataFormatError(f"{name}: Vxyzf contains NaN or infinite values")
    return velocity.astype(np.float64)


# --- npz -------------------------------------------------------------------------------------------


def save_npz(library: ReachLibrary, path: PathLike) -> None:
    """Save a library as a compressed ``.npz`` archive, written exactly at ``path``.

    The archive holds one array per :class:`ReachLibrary` field:

    - ``velocity``: (n, max_len, 3) float64, mm/s, zero after each movement's end;
    - ``position``: (n, max_len, 3) float64, mm, holding the last position after the end;
    - ``length``: (n,) int64, samples per movement, 1..max_len;
    - ``fear``: (n,) bool;
    - ``subject``: (n,) int64, participant index;
    - ``target``: (n,) int64, cube 0 or 1, -1 if unknown;
    - ``dt``: () float64, sampling time in seconds.
    """
    with open(path, "wb") as stream:
        np.savez_compressed(
            stream,
            velocity=library.velocity,
            position=library.position,
            length=library.length.astype(np.int64),
            fear=library.fear.astype(bool),
            subject=library.subject.astype(np.int64),
            target=library.target.astype(np.int64),
            dt=np.float64(library.dt),
        )


def load_npz(
    path: PathLike, *, label_field: str = "fear", dt: float | None = None, unit: str | None = None
) -> ReachLibrary:
    """Load a library saved by :func:`save_npz` (see there for the keys and shapes).

    ``label_field`` names the key of the fear label; ``dt`` (seconds), when given, replaces the
    archive's ``dt``, which may then be absent. ``unit`` (m, cm or mm) is the length unit of
    ``position`` (``velocity`` in ``unit``/s), converted to mm; by default the archive's ``unit``
    key (a string) if it has one, else mm.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    DataFormatError
        If the file is not an npz archive, lacks a key, or holds arrays of the wrong type or shape.
    """
    file = _existing_file(path)
    if unit is not None:
        to_mm(unit, "load_npz: unit")
    try:
        archive = np.load(file, allow_pickle=False)
    except (OSError, EOFError, ValueError, zipfile.BadZipFile) as error:
        raise DataFormatError(f"{file}: not an npz archive ({_unreadable(error)})") from error
    if not isinstance(archive, np.lib.npyio.NpzFile):
        raise DataFormatError(f"{file}: not an npz archive (a single .npy array)")
    with archive:
        names = {key: label_field if key == "fear" else key for key in _NPZ_KEYS if key != "dt" or dt is None}
        missing = [name for name in names.values() if name not in archive.files]
        if missing:
            hint = (_LABEL_HINT if label_field in missing else "") + (_DT_HINT if "dt" in missing else "")
            raise DataFormatError(
                f"{file}: missing key(s) {', '.join(map(repr, missing))} (keys: {', '.join(archive.files)}){hint}"
            )
        arrays = {} if dt is None else {"dt": np.float64(dt)}
        for key, name in names.items():
            try:
                arrays[key] = archive[name]
            except (OSError, ValueError, zipfile.BadZipFile) as error:  # object arrays need pickle: refused
                raise DataFormatError(f"{file}: key '{key}' is unreadable ({_unreadable(error)})") from error
        if unit is None:
            unit = str(archive["unit"]) if "unit" in archive.files and archive["unit"].dtype.kind == "U" else "mm"
    try:
        scale = to_mm(unit, f"{file}: unit")
    except ValueError as error:
        raise DataFormatError(str(error)) from None
    arrays["velocity"] = arrays["velocity"] * scale if _is_real(arrays["velocity"].dtype) else arrays["velocity"]
    arrays["position"] = arrays["position"] * scale if _is_real(arrays["position"].dtype) else arrays["position"]
    for key, array in arrays.items():
        if not _is_real(array.dtype):
            raise DataFormatError(f"{file}: key '{key}' is not numeric (dtype {array.dtype})")
    if arrays["dt"].shape != ():
        raise DataFormatError(f"{file}: key 'dt' must be a scalar, got shape {arrays['dt'].shape}")
    try:
        return ReachLibrary(**{key: arrays[key] for key in _NPZ_KEYS[:-1]}, dt=float(arrays["dt"]))
    except ValueError as error:
        raise DataFormatError(f"{file}: {error}") from error


# --- CSV -------------------------------------------------------------------------------------------


def save_csv(library: ReachLibrary, path: PathLike) -> None:
    """Save a library as a long-format CSV file, one row per sample of each movement.

    Columns, in order: ``movement`` (index of the movement in the library), ``subject``, ``fear``
    (0 or 1), ``target`` (0, 1 or -1 for unknown), ``t`` (sample index within the movement,
    0..length-1; time is ``t * dt``), ``px, py, pz`` (position, mm) and ``vx, vy, vz`` (velocity,
    mm/s). Only each movement's own samples are written, not its padding, and ``dt`` is not stored.
    Floats are written with 17 significant digits, so a round trip is exact.
    """
    blocks = []
    for i in range(len(library)):
        n = int(library.length[i])
        labels = np.tile([i, library.subject[i], int(library.fear[i]), library.target[i]], (n, 1))
        blocks.append(np.column_stack([labels, np.arange(n), library.position[i, :n], library.velocity[i, :n]]))
    table = np.concatenate(blocks) if blocks else np.empty((0, len(CSV_COLUMNS)))
    np.savetxt(path, table, fmt=["%d"] * 5 + ["%.17g"] * 6, delimiter=",", header=",".join(CSV_COLUMNS), comments="")


def load_csv(
    path: PathLike, max_len: int = 200, dt: float = 0.01, *, label_field: str = "fear", unit: str = "mm"
) -> ReachLibrary:
    """Load a long-format CSV file written by :func:`save_csv` (see there for the columns).

    Columns may come in any order and extra columns are ignored. Movements keep the order of
    their first row; within a movement, rows may come in any order but ``t`` must cover
    ``0 .. T-1`` exactly once, and ``subject``, ``fear`` and ``target`` must not change. A UTF-8
    byte order mark is skipped. Time and memory are linear in the number of rows.

    Parameters
    ----------
    path : str or os.PathLike
        The CSV file.
    max_len : int
        Padded number of samples; a longer movement raises :class:`DataFormatError`.
    dt : float
        Sampling time in seconds (not stored in the file).
    label_field : str
        The column of the fear label (``fear``).
    unit : {"mm", "cm", "m"}
        Length unit of ``px, py, pz`` (``vx, vy, vz`` in ``unit``/s), converted to mm.

    Returns
    -------
    ReachLibrary

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    IsADirectoryError
        If ``path`` is a directory.
    DataFormatError
        If the file is empty, lacks a column, or holds non-numeric, non-finite or inconsistent values.
    """
    file = _existing_file(path)
    scale = to_mm(unit, "load_csv: unit")
    table, lines = _read_csv_table(file, label_field)
    bad = ~np.isfinite(table)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise DataFormatError(f"{file}: line {lines[row]}, column '{CSV_COLUMNS[col]}': value is NaN or infinite")
    integral = table[:, :5]
    if np.any(integral != np.round(integral)):
        row, col = np.argwhere(integral != np.round(integral))[0]
        raise DataFormatError(f"{file}: line {lines[row]}, column '{CSV_COLUMNS[col]}': expected an integer")

    # One sort by (movement, t) groups the rows: linear in the movements after it, where selecting each
    # movement's rows from the whole table would be quadratic.
    order = np.lexsort((table[:, 4], table[:, 0]))
    table = table[order]
    starts = np.flatnonzero(np.r_[True, table[1:, 0] != table[:-1, 0]])
    ends = np.r_[starts[1:], len(table)]
    first_rows = np.minimum.reduceat(order, starts)  # movements keep the order of their first row
    velocities: list[np.ndarray] = []
    positions: list[np.ndarray] = []
    labels: dict[str, list[int]] = {"fear": [], "subject": [], "target": []}
    for m in np.argsort(first_rows):
        rows_of_movement = table[starts[m] : ends[m]]
        movement, n = rows_of_movement[0, 0], len(rows_of_movement)
        if not np.array_equal(rows_of_movement[:, 4], np.arange(n)):
            raise DataFormatError(f"{file}: movement {movement:g}: t must be 0..{n - 1}, each once")
        if n > max_len:
            raise DataFormatError(f"{file}: movement {movement:g}: {n} samples, more than max_len={max_len}")
        for column, name in ((1, "subject"), (2, "fear"), (3, "target")):
            if np.any(rows_of_movement[:, column] != rows_of_movement[0, column]):
                raise DataFormatError(f"{file}: movement {movement:g}: '{name}' changes within the movement")
            labels[name].append(int(rows_of_movement[0, column]))
        positions.append(rows_of_movement[:, 5:8])
        velocities.append(rows_of_movement[:, 8:11])
    return _library_from_movements(file, velocities, positions, labels, max_len, dt, scale)


def _read_csv_table(file: Path, label_field: str) -> tuple[np.ndarray, np.ndarray]:
    """The known columns of a CSV file as floats (:data:`CSV_COLUMNS` order) and each row's line number.

    The column ``label_field`` stands for ``fear`` when the file has no ``fear`` column.

    Rows are parsed as they are read, into flat arrays of numbers, so memory stays a few numbers per
    cell rather than a Python string per cell. A UTF-8 byte order mark is skipped.
    """
    values, lines = flat_array("d"), flat_array("q")
    try:
        with open(file, newline="", encoding="utf-8-sig") as stream:
            reader = csv.reader(stream)
            header = [cell.strip() for cell in next(reader, [])]
            if not any(header):
                raise DataFormatError(f"{file}: empty file (expected a header with columns {', '.join(CSV_COLUMNS)})")
            if label_field != "fear" and label_field in header and "fear" not in header:
                header[header.index(label_field)] = "fear"
            columns = _column_indices(file, header)
            for line, row in enumerate(reader, start=2):
                if not any(cell.strip() for cell in row):
                    continue
                if len(row) != len(header):
                    raise DataFormatError(f"{file}: line {line}: {len(row)} fields, the header has {len(header)}")
                try:
                    values.extend([float(row[k]) for k in columns])
                except ValueError:
                    name, text = next(
                        (name, row[k]) for name, k in zip(CSV_COLUMNS, columns, strict=True) if not _is_number(row[k])
                    )
                    raise DataFormatError(f"{file}: line {line}, column '{name}': {text!r} is not a number") from None
                lines.append(line)
    except (UnicodeDecodeError, csv.Error) as error:
        raise DataFormatError(f"{file}: not a CSV text file ({error})") from error
    if not lines:
        raise DataFormatError(f"{file}: no data rows after the header")
    return np.frombuffer(values, dtype=np.float64).reshape(-1, len(CSV_COLUMNS)), np.frombuffer(lines, dtype=np.int64)


def _column_indices(file: Path, header: list[str]) -> list[int]:
    """Where each of :data:`CSV_COLUMNS` is in the header."""
    missing = [column for column in CSV_COLUMNS if column not in header]
    if missing:
        hint = _LABEL_HINT if "fear" in missing else ""
        raise DataFormatError(f"{file}: missing column(s) {', '.join(map(repr, missing))}{hint}")
    duplicated = sorted({column for column in CSV_COLUMNS if header.count(column) > 1})
    if duplicated:
        raise DataFormatError(f"{file}: duplicated column(s) {', '.join(map(repr, duplicated))}")
    return [header.index(column) for column in CSV_COLUMNS]


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
