"""The restricted solution function w̃ (Algorithm 1 of the appendix), computed offline and cached on disk."""

from __future__ import annotations

import hashlib
import os
import tempfile
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from cogblocks.amplification.encoder import CLIP_HIGH, REST_SPEED, EncoderNet, resampling_matrix
from cogblocks.data.reach import ReachLibrary
from cogblocks.sim.params import finite_number, one_of, positive_int
from cogblocks.sim.reading import FileFormatError, open_npz

__all__ = [
    "SolutionTable",
    "default_cache_dir",
    "library_fingerprint",
    "library_summary",
    "same_library",
    "solution_table",
]

GRID_POINTS = 50  # values of the blending coefficient, 0 and 1 included


def library_fingerprint(library: ReachLibrary) -> str:
    """SHA-256 of a library's velocities, lengths and labels: which data a set of weights was trained on."""
    digest = hashlib.sha256()
    for array in (library.velocity, library.length, library.fear):
        digest.update(np.ascontiguousarray(array).tobytes())
    return digest.hexdigest()


def library_summary(library: ReachLibrary) -> dict[str, list]:
    """Per movement: its length, its label, and the sum and the sum of squares of its velocity samples.

    What a set of weights was trained on, up to rounding: :func:`library_fingerprint` changes with the last bit of
    any sample, which the generator's floating point does from one CPU or NumPy / SciPy build to another.
    """
    velocity = np.asarray(library.velocity, dtype=float).reshape(len(library.length), -1)
    return {
        "length": np.asarray(library.length).astype(int).tolist(),
        "fear": np.asarray(library.fear).astype(bool).tolist(),
        "velocity_sum": velocity.sum(axis=1).tolist(),
        "velocity_squares": (velocity**2).sum(axis=1).tolist(),
    }


def same_library(summary: dict[str, list], library: ReachLibrary, rtol: float = 1e-9) -> bool:
    """Whether ``library`` is the one ``summary`` (:func:`library_summary`) was taken of, to ``rtol`` of its scale.

    Lengths and labels must be equal; the velocity sums may differ by ``rtol`` times the largest of them, far above
    rounding (about 1e-13 of it) and far below any change of the generator.
    """
    here = library_summary(library)
    if here["length"] != list(summary["length"]) or here["fear"] != list(summary["fear"]):
        return False
    for key in ("velocity_sum", "velocity_squares"):
        want, got = np.asarray(summary[key], dtype=float), np.asarray(here[key], dtype=float)
        scale = float(np.abs(want).max(initial=0.0))
        if want.shape != got.shape or not np.allclose(got, want, rtol=0.0, atol=rtol * max(scale, 1.0)):
            return False
    return True


# --- the restricted solution function w̃ --------------------------------------------------------


@dataclass
class SolutionTable:
    """The restricted solution function w̃(e_des, ·, ·) on a library.

    Attributes
    ----------
    values : numpy.ndarray, shape (len(rows), len(cols))
        The blending coefficient of each pair, on the grid of ``grid``.
    rows : numpy.ndarray of int
        Library indices of the movements that do not encode ``e_des`` (the set D₋).
    cols : numpy.ndarray of int
        Library indices of the movements that do (D₊, where the reference comes from).
    e_des : int
        Desired encoding level (1: encode fear, 0: remove it).
    grid : numpy.ndarray
        The grid of blending coefficients.
    """

    values: np.ndarray
    rows: np.ndarray
    cols: np.ndarray
    e_des: int
    grid: np.ndarray
    _row_of: np.ndarray = field(init=False, repr=False)
    _col_of: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        size = int(max(self.rows.max(initial=-1), self.cols.max(initial=-1))) + 1
        self._row_of = np.full(size, -1, dtype=np.int64)
        self._col_of = np.full(size, -1, dtype=np.int64)
        self._row_of[self.rows] = np.arange(len(self.rows))
        self._col_of[self.cols] = np.arange(len(self.cols))

    def lookup(self, nearest: int, reference: int) -> float:
        """w̃ for the library movements ``nearest`` (in ``rows``) and ``reference`` (in ``cols``)."""
        i = self._row_of[nearest] if 0 <= nearest < len(self._row_of) else -1
        j = self._col_of[reference] if 0 <= reference < len(self._col_of) else -1
        if i < 0 or j < 0:
            raise KeyError(f"no w̃ entry for the pair (nearest={nearest}, reference={reference})")
        return float(self.values[i, j])


def default_cache_dir() -> Path:
    """Where :func:`solution_table` keeps its cache: ``$COGBLOCKS_CACHE`` or ``~/.cache/cogblocks``."""
    if "COGBLOCKS_CACHE" in os.environ:
        return Path(os.environ["COGBLOCKS_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "cogblocks"


def solution_table(
    network: EncoderNet,
    library: ReachLibrary,
    e_des: int = 1,
    *,
    grid_points: int = GRID_POINTS,
    threshold: float = CLIP_HIGH,
    rest_speed: float = REST_SPEED,
    cache_dir: str | os.PathLike | None = "default",
    chunk: int = 512,
) -> SolutionTable:
    """Compute the restricted solution function w̃ on a library (Algorithm 1), vectorised and cached.

    For each pair (``v_ne`` not encoding ``e_des``, ``v_r`` encoding it), w̃ is the largest ``c`` on
    the grid such that the blend ``c·v_ne + (1 − c)·v_r`` of the padded signals scores at least
    ``threshold``; the score is ε̂ for ``e_des = 1`` and ``1 − ε̂`` for ``e_des = 0``. When no ``c``
    reaches it, the threshold becomes ``threshold · score(c = 0)`` (the prototype's fallback), which
    ``c = 0`` always meets. Each blend is classified as :class:`EncoderClassifier` classifies the
    altered movement online: restricted to its samples up to the last one faster than
    ``rest_speed`` (:func:`movement_length`), resampled to 20 points per axis.

    Resampling and the network's first layer are affine in the signal, so every movement is
    resampled and passed through the first layer once per restriction length; the blends of all
    pairs and all grid values are then formed in hidden space and finished in large tensors.

    Parameters
    ----------
    network : EncoderNet
        The classifier (its dtype is used throughout).
    library : ReachLibrary
        The movement library; both sets must be non-empty.
    e_des : {0, 1}
        Desired encoding level.
    grid_points : int
        Values of ``c`` in [0, 1], both ends included (50).
    threshold : float
        Score a blend must reach, in (0, 1].
    rest_speed : float
        Speed (mm/s) at or below which a blend is at rest.
    cache_dir : path-like or None
        Directory of the npz cache, keyed by a hash of the network's weights, the library and the
        parameters; ``"default"`` is :func:`default_cache_dir`, ``None`` disables the cache.
    chunk : int
        Pairs per batch (memory: about ``chunk × grid_points × (hidden + max_len)`` numbers).

    Returns
    -------
    SolutionTable
    """
    e_des = one_of("solution_table", "e_des", e_des, (0, 1))
    grid_points = positive_int("solution_table", "grid_points", grid_points, minimum=2)
    threshold = finite_number("solution_table", "threshold", threshold, low=0.0, high=1.0, low_open=True)
    rest_speed = finite_number("solution_table", "rest_speed", rest_speed, low=0.0)
    rows = np.flatnonzero(library.fear != bool(e_des))
    cols = np.flatnonzero(library.fear == bool(e_des))
    if rows.size == 0 or cols.size == 0:
        raise ValueError("solution_table: the library needs movements both with and without the encoded emotion")
    grid = np.linspace(0.0, 1.0, grid_points)
    path = None
    if cache_dir is not None:
        directory = default_cache_dir() if cache_dir == "default" else Path(cache_dir)
        key = _table_key(network, library, e_des, grid_points, threshold, rest_speed)
        path = directory / f"w_tilde_{key[:20]}.npz"
        cached = _read_cache(path, key, (len(rows), len(cols)))
        if cached is not None:
            return SolutionTable(cached, rows, cols, e_des, grid)
    values = _solve(network, library, rows, cols, e_des, grid, threshold, rest_speed, chunk)
    if path is not None:
        _write_cache(path, values=values, key=np.array(key))
    return SolutionTable(values, rows, cols, e_des, grid)


def _read_cache(path: Path, key: str, shape: tuple[int, int]) -> np.ndarray | None:
    """The cached table at ``path``, or None when there is none or it is unreadable (warned, then rebuilt)."""
    if not path.exists():
        return None
    try:
        with open_npz(path, "w̃ cache") as cached:
            if str(cached["key"]) != key:  # the first 20 hex digits of another key: rebuilt, not an error
                return None
            values = cached["values"]
        if values.shape != shape or not np.all((values >= 0.0) & (values <= 1.0)):
            raise FileFormatError(f"values of shape {values.shape} outside [0, 1] or not {shape}")
    except (OSError, FileFormatError) as error:
        why = str(error).removeprefix(f"{path}: ")
        warnings.warn(f"{path}: corrupt w̃ cache file ({why}); rebuilding it", stacklevel=3)
        return None
    return values


def _write_cache(path: Path, **arrays: np.ndarray) -> None:
    """Write an npz file atomically: a reader, even in another process, never sees half a file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    descriptor, partial = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(descriptor, "wb") as stream:
            np.savez(stream, **arrays)
        os.replace(partial, path)
    except BaseException:
        Path(partial).unlink(missing_ok=True)
        raise


def _table_key(
    network: EncoderNet, library: ReachLibrary, e_des: int, grid_points: int, threshold: float, rest_speed: float
) -> str:
    digest = hashlib.sha256(f"w-tilde/2/{e_des}/{grid_points}/{threshold!r}/{rest_speed!r}".encode())
    for name, tensor in sorted(network.state_dict().items()):
        digest.update(name.encode())
        digest.update(tensor.detach().cpu().contiguous().numpy().tobytes())
    digest.update(library_fingerprint(library).encode())
    digest.update(resampling_matrix(7).tobytes())  # a change of the interpolation invalidates the cache
    return digest.hexdigest()


def _solve(
    network: EncoderNet,
    library: ReachLibrary,
    rows: np.ndarray,
    cols: np.ndarray,
    e_des: int,
    grid: np.ndarray,
    threshold: float,
    rest_speed: float,
    chunk: int,
) -> np.ndarray:
    network.eval()
    dtype = network.out.weight.dtype
    members = np.concatenate([rows, cols])
    span = int(library.length[members].max())  # past it every blend is at rest
    velocity = library.velocity[members, :span]
    speed2 = np.einsum("nta,nta->nt", velocity, velocity)
    c = grid[None, :, None]
    with torch.no_grad():
        # hidden pre-activations of every member restricted to every length 1 … span (row 0: length 0)
        hidden = torch.zeros((span + 1, len(members), network.hidden.out_features), dtype=dtype)
        for length in range(1, span + 1):
            features = np.einsum("pl,nla->nap", resampling_matrix(length), velocity[:, :length])
            hidden[length] = network.preactivation(torch.as_tensor(features.reshape(len(members), -1), dtype=dtype))
        n_cols = len(cols)
        n_pairs = len(rows) * n_cols
        index = np.empty(n_pairs, dtype=np.int64)
        steps = np.arange(1, span + 1)
        for start in range(0, n_pairs, chunk):
            pairs = np.arange(start, min(start + chunk, n_pairs))
            i, j = pairs // n_cols, len(rows) + pairs % n_cols
            # restricted length of every blend: ‖c a + (1 − c) b‖² from |a|², a·b and |b|²
            cross = np.einsum("pta,pta->pt", velocity[i], velocity[j])[:, None, :]
            blend2 = c**2 * speed2[i][:, None, :] + 2 * c * (1 - c) * cross + (1 - c) ** 2 * speed2[j][:, None, :]
            length = np.max(np.where(blend2 > rest_speed**2, steps, 0), axis=2)  # (pairs, grid)
            level = torch.as_tensor(length)
            h_ne = hidden[level, torch.as_tensor(i)[:, None]]
            h_r = hidden[level, torch.as_tensor(j)[:, None]]
            weight = torch.as_tensor(c, dtype=dtype)
            eps = network.head(weight * h_ne + (1.0 - weight) * h_r).double().numpy()
            score = np.where(length > 0, eps if e_des == 1 else 1.0 - eps, 0.0)
            ok = score >= threshold
            fallback = ~ok.any(axis=1)
            ok[fallback] = score[fallback] >= threshold * score[fallback, :1]
            index[start : start + len(pairs)] = len(grid) - 1 - np.argmax(ok[:, ::-1], axis=1)
    return grid[index].reshape(len(rows), n_cols)
