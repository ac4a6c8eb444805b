"""Reach-to-grasp libraries as long-format CSV: one row per sample of each movement (:data:`CSV_COLUMNS`)."""

from __future__ import annotations

import csv
from array import array as flat_array
from pathlib import Path

import numpy as np

from cogblocks.data.formats import LABEL_HINT, DataFormatError, PathLike, existing_file, library_from_movements
from cogblocks.data.reach import ReachLibrary
from cogblocks.data.units import to_mm
from cogblocks.sim.timing import BASE_STEP

__all__ = ["CSV_COLUMNS", "load_csv", "save_csv"]

CSV_COLUMNS = ("movement", "subject", "fear", "target", "t", "px", "py", "pz", "vx", "vy", "vz")


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
    path: PathLike, max_len: int = 200, dt: float = BASE_STEP, *, label_field: str = "fear", unit: str = "mm"
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
    file = existing_file(path)
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
    return library_from_movements(file, velocities, positions, labels, max_len, dt, scale)


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
        hint = LABEL_HINT if "fear" in missing else ""
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
