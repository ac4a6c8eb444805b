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

import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import scipy.io

from cogblocks.data.formats import (
    DT_HINT,
    LABEL_HINT,
    DataFormatError,
    PathLike,
    existing_file,
    is_real,
    library_from_movements,
    unreadable,
)
from cogblocks.data.reach import ReachLibrary
from cogblocks.data.reach_csv import CSV_COLUMNS, load_csv, save_csv
from cogblocks.data.units import to_mm
from cogblocks.sim.timing import BASE_STEP

__all__ = [
    "CSV_COLUMNS",
    "DataFormatError",
    "load_csv",
    "load_npz",
    "load_velocity_data_mat",
    "save_csv",
    "save_npz",
]

_NPZ_KEYS = ("velocity", "position", "length", "fear", "subject", "target", "dt")
_PHASES = ("BASELINE", "ASSOCIATION", "EXTINCTION")
# The conditioned trials the prototype keeps with their Condition label; other subphases are dropped.
_KEPT_SUBPHASE = {"ASSOCIATION": 3, "EXTINCTION": 1}


# --- MATLAB layout of the real data set ------------------------------------------------------------


def load_velocity_data_mat(
    path: PathLike,
    max_len: int = 200,
    dt: float = BASE_STEP,
    *,
    label_field: str = "Condition",
    unit: str = "mm",
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
    file = existing_file(path)
    scale = to_mm(unit, "load_velocity_data_mat: unit")
    try:
        content = scipy.io.loadmat(file, squeeze_me=True, struct_as_record=False)
    except Exception as error:  # scipy raises whatever its parser met (IndexError, zlib.error, MatReadError, ...)
        why = unreadable(error) or type(error).__name__
        raise DataFormatError(f"{file}: not a readable MATLAB file ({why})") from None
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
    return library_from_movements(file, velocities, positions, labels, max_len, dt, scale)


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
    if array.size != 1 or not is_real(array.dtype):
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
    condition = _scalar(name, label_field, _trial_field(name, trial, label_field, LABEL_HINT))
    if condition not in (0.0, 1.0):
        raise DataFormatError(f"{name}: {label_field} must be 0 (no fear) or 1 (fear), got {condition:g}")
    return condition == 1.0


def _trial_velocity(name: str, trial: Any) -> np.ndarray:
    raw = _trial_field(name, trial, "Vxyzf")
    velocity = np.asarray(raw)
    if not is_real(velocity.dtype):
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
    file = existing_file(path)
    if unit is not None:
        to_mm(unit, "load_npz: unit")
    try:
        archive = np.load(file, allow_pickle=False)
    except (OSError, EOFError, ValueError, zipfile.BadZipFile) as error:
        raise DataFormatError(f"{file}: not an npz archive ({unreadable(error)})") from error
    if not isinstance(archive, np.lib.npyio.NpzFile):
        raise DataFormatError(f"{file}: not an npz archive (a single .npy array)")
    with archive:
        names = {key: label_field if key == "fear" else key for key in _NPZ_KEYS if key != "dt" or dt is None}
        missing = [name for name in names.values() if name not in archive.files]
        if missing:
            hint = (LABEL_HINT if label_field in missing else "") + (DT_HINT if "dt" in missing else "")
            raise DataFormatError(
                f"{file}: missing key(s) {', '.join(map(repr, missing))} (keys: {', '.join(archive.files)}){hint}"
            )
        arrays = {} if dt is None else {"dt": np.float64(dt)}
        for key, name in names.items():
            try:
                arrays[key] = archive[name]
            except (OSError, ValueError, zipfile.BadZipFile) as error:  # object arrays need pickle: refused
                raise DataFormatError(f"{file}: key '{key}' is unreadable ({unreadable(error)})") from error
        if unit is None:
            unit = str(archive["unit"]) if "unit" in archive.files and archive["unit"].dtype.kind == "U" else "mm"
    try:
        scale = to_mm(unit, f"{file}: unit")
    except ValueError as error:
        raise DataFormatError(str(error)) from None
    arrays["velocity"] = arrays["velocity"] * scale if is_real(arrays["velocity"].dtype) else arrays["velocity"]
    arrays["position"] = arrays["position"] * scale if is_real(arrays["position"].dtype) else arrays["position"]
    for key, array in arrays.items():
        if not is_real(array.dtype):
            raise DataFormatError(f"{file}: key '{key}' is not numeric (dtype {array.dtype})")
    if arrays["dt"].shape != ():
        raise DataFormatError(f"{file}: key 'dt' must be a scalar, got shape {arrays['dt'].shape}")
    try:
        return ReachLibrary(**{key: arrays[key] for key in _NPZ_KEYS[:-1]}, dt=float(arrays["dt"]))
    except ValueError as error:
        raise DataFormatError(f"{file}: {error}") from error
