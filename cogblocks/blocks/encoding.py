"""PoP of Amplification: encoding classifier, restricted solution function, online projection and blending.

The L2 architecture of the appendix paper (sections III–V) alters a human reach-to-grasp movement so
that it encodes fear (``e_des = 1``) or stops encoding it (``e_des = 0``):

* :class:`EncoderNet` approximates the encoding function ε̂ (60 inputs → 200 ReLU + dropout → 1
  sigmoid); :func:`clip_decision` applies the clipping rule (ε̂ > 0.9 fear, ε̂ < 0.1 no fear, else
  undecided); :class:`EncoderClassifier` classifies a buffered movement online.
* :func:`solution_table` computes the restricted solution function w̃ (Algorithm 1): for every pair
  of a library movement that does not encode ``e_des`` and one that does, the largest blending
  coefficient ``c`` on a 50-point grid whose blend ``c·v_ne + (1 − c)·v_r`` the classifier decides
  as ``e_des``.
* :class:`LibraryProjector` projects the buffered prefix of the human movement onto the library's
  prefixes every ΔT samples, incrementally; :class:`VelocityBlender` looks ``c`` up in w̃ and
  blends, ``v_a = c·v_h + (1 − c)·v_r + v_u``; :class:`PositionComputer` integrates ``v_a``.

Conventions: velocities in mm/s, positions in mm, one sample per 10 ms tick. A library movement is
padded to the library's length with zero velocity, and a movement is *restricted* to its own
samples before it is resampled to 20 points per axis (:func:`cogblocks.data.features.resample_movement`).
"""

from __future__ import annotations

import hashlib
import math
import os
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from cogblocks.blocks.buffer import ordered_window
from cogblocks.blocks.samples import PLAUSIBLE, plausible
from cogblocks.data.features import resample_movement
from cogblocks.data.reach import ReachLibrary
from cogblocks.sim import Block, Signal
from cogblocks.sim.params import finite_number, one_of, positive_int

__all__ = [
    "BLENDING_INPUTS",
    "BLENDING_OUTPUTS",
    "CLIP_HIGH",
    "CLIP_LOW",
    "REST_SPEED",
    "FEAR",
    "NO_FEAR",
    "UNDECIDED",
    "EncoderClassifier",
    "EncoderNet",
    "LibraryProjector",
    "PositionComputer",
    "PrefixProjection",
    "SolutionTable",
    "VelocityBlender",
    "add_blending_ports",
    "blend",
    "clip_decision",
    "default_cache_dir",
    "library_fingerprint",
    "load_encoder",
    "movement_length",
    "resampling_matrix",
    "solution_table",
]

POSITION = Signal(shape=(3,), unit="mm")
VELOCITY = Signal(shape=(3,), unit="mm/s")
COUNT = Signal(dtype=np.int64, unit="1")

FEAR, NO_FEAR, UNDECIDED = 1, 0, -1
CLIP_HIGH, CLIP_LOW = 0.9, 0.1
N_POINTS = 20  # resampled points per axis: 60 classifier inputs
GRID_POINTS = 50  # values of the blending coefficient, 0 and 1 included
REST_SPEED = 1.0  # mm/s: a movement has ended once the hand stays at or below this speed

ENCODER_WEIGHTS = "encoder.pt"


def clip_decision(eps_hat: Any) -> np.ndarray:
    """The clipping rule: ``FEAR`` (1) above 0.9, ``NO_FEAR`` (0) below 0.1, ``UNDECIDED`` (−1) between.

    Parameters
    ----------
    eps_hat : array_like
        Classifier outputs in [0, 1]. NaN is undecided.

    Returns
    -------
    numpy.ndarray of int64, the shape of ``eps_hat``
    """
    eps = np.asarray(eps_hat, dtype=np.float64)
    decision = np.full(eps.shape, UNDECIDED, dtype=np.int64)
    decision[eps > CLIP_HIGH] = FEAR
    decision[eps < CLIP_LOW] = NO_FEAR
    return decision


class EncoderNet(nn.Module):
    """The approximate encoding function ε̂: 60 inputs → 200 ReLU units with dropout → 1 sigmoid.

    The inputs (20 resampled velocity points per axis, axis-major, mm/s) are standardised with a
    per-input mean and scale stored in the network's buffers, so that the saved weights carry their
    own normalisation (:meth:`set_normalisation`).

    Parameters
    ----------
    n_inputs : int
        Number of inputs (60).
    hidden : int
        Hidden ReLU units (200).
    dropout : float
        Dropout probability on the hidden units during training.
    """

    def __init__(self, n_inputs: int = 3 * N_POINTS, hidden: int = 200, dropout: float = 0.2) -> None:
        super().__init__()
        self.register_buffer("mean", torch.zeros(n_inputs))
        self.register_buffer("scale", torch.ones(n_inputs))
        self.hidden = nn.Linear(n_inputs, hidden)
        self.dropout = nn.Dropout(dropout)
        self.out = nn.Linear(hidden, 1)

    def set_normalisation(self, inputs: np.ndarray) -> None:
        """Standardise inputs with the mean and standard deviation of ``inputs`` (n, 60)."""
        x = np.asarray(inputs, dtype=np.float64)
        std = x.std(axis=0)
        self.mean.copy_(torch.as_tensor(x.mean(axis=0)))
        self.scale.copy_(torch.as_tensor(np.where(std > 0, std, 1.0)))

    def preactivation(self, x: torch.Tensor) -> torch.Tensor:
        """Hidden pre-activations, an affine function of the inputs: shape (..., hidden)."""
        return self.hidden((x - self.mean) / self.scale)

    def head(self, pre: torch.Tensor) -> torch.Tensor:
        """ε̂ from hidden pre-activations: shape (...,)."""
        return torch.sigmoid(self.out(self.dropout(torch.relu(pre)))).squeeze(-1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """ε̂ of inputs of shape (..., 60), shape (...,)."""
        return self.head(self.preactivation(x))

    def predict(self, inputs: np.ndarray) -> np.ndarray:
        """ε̂ of a NumPy array of inputs (..., 60), in evaluation mode, as float64."""
        was_training = self.training
        self.eval()
        try:
            with torch.no_grad():
                dtype = self.out.weight.dtype
                return self(torch.as_tensor(np.asarray(inputs), dtype=dtype)).double().numpy()
        finally:
            self.train(was_training)


def load_encoder(path: str | os.PathLike | None = None) -> EncoderNet:
    """Load an :class:`EncoderNet` saved by ``python -m cogblocks.training.encoder``.

    Parameters
    ----------
    path : path-like, optional
        The checkpoint; the shipped ``cogblocks/data/weights/encoder.pt`` by default.

    Returns
    -------
    EncoderNet
        In evaluation mode; the checkpoint's metadata (split, cross-validation) is in
        ``network.checkpoint``.
    """
    checkpoint = _load_checkpoint(path)
    network = EncoderNet(hidden=checkpoint["hidden"], dropout=checkpoint["dropout"])
    network.load_state_dict(checkpoint["state_dict"])
    network.eval()
    network.checkpoint = {k: v for k, v in checkpoint.items() if k != "state_dict"}
    return network


def _load_checkpoint(path: str | os.PathLike | None) -> dict[str, Any]:
    if path is None:
        with resources.as_file(resources.files("cogblocks.data") / "weights" / ENCODER_WEIGHTS) as p:
            return torch.load(p, weights_only=True)
    return torch.load(Path(path), weights_only=True)


def library_fingerprint(library: ReachLibrary) -> str:
    """SHA-256 of a library's velocities, lengths and labels: which data a set of weights was trained on."""
    digest = hashlib.sha256()
    for array in (library.velocity, library.length, library.fear):
        digest.update(np.ascontiguousarray(array).tobytes())
    return digest.hexdigest()


def movement_length(velocity: np.ndarray, rest_speed: float) -> int:
    """Samples of a movement up to its last one faster than ``rest_speed`` (0 if none is).

    This is the restriction of a buffered or padded movement to its own duration: what follows
    is the rest after the terminal instant.
    """
    moving = np.flatnonzero(np.linalg.norm(velocity, axis=1) > rest_speed)
    return int(moving[-1]) + 1 if moving.size else 0


@lru_cache(maxsize=1024)
def resampling_matrix(length: int, n_points: int = N_POINTS) -> np.ndarray:
    """The linear map of :func:`~cogblocks.data.features.resample_movement` for one length (read-only).

    Resampling a signal of ``length`` samples is linear in the samples, so it is a matrix
    ``R`` of shape ``(n_points, length)`` with ``resampled = R @ samples``: what lets w̃ be computed
    on all pairs at once, and the online classifier skip fitting a spline at every tick.
    """
    matrix = resample_movement(np.eye(length), length, n_points).reshape(length, n_points).T.copy()
    matrix.flags.writeable = False
    return matrix


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
        if path.exists():
            with np.load(path) as cached:
                if str(cached["key"]) == key:
                    return SolutionTable(cached["values"], rows, cols, e_des, grid)
    values = _solve(network, library, rows, cols, e_des, grid, threshold, rest_speed, chunk)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        partial = path.with_name(f"{path.stem}.{os.getpid()}.tmp.npz")
        np.savez(partial, values=values, key=np.array(key))
        os.replace(partial, path)  # atomic: a concurrent reader never sees half a file
    return SolutionTable(values, rows, cols, e_des, grid)


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


# --- blocks -----------------------------------------------------------------------------------------


class EncoderClassifier(Block):
    """ε̂ and the clipped decision of a buffered movement, recomputed at every run of the block.

    The buffered samples (oldest first) are restricted to the movement's own duration, up to the
    last sample faster than ``rest_speed`` (:func:`movement_length`), resampled to 20 points per axis
    and classified.

    Ports
    -----
    velocity : input, shape (capacity, 3), mm/s
        A velocity ring from :class:`~cogblocks.blocks.buffer.Buffer`.
    count : input, int64
        Samples received by the buffer.
    eps : output, scalar
        ε̂ in [0, 1]; NaN until the movement has started.
    decision : output, int64
        :func:`clip_decision` of ``eps``: 1 fear, 0 no fear, −1 undecided.
    length : output, int64
        Samples classified (the restricted length).

    Parameters
    ----------
    network : EncoderNet
        The classifier.
    rest_speed : float
        Speed (mm/s, >= 0) at or below which the hand is at rest.

    Notes
    -----
    With samples lost off the start of a full ring, what is classified is the newest ``capacity``
    samples.

    Bad data policy: the buffer upstream replaces non-finite and implausible samples; fed
    directly, a window holding a sample beyond 1 km/s
    (:func:`~cogblocks.blocks.samples.plausible`) is not classified and the outputs hold.
    """

    def __init__(self, network: EncoderNet, *, rest_speed: float = REST_SPEED, period: float | None = None) -> None:
        super().__init__(period=period)
        if not isinstance(network, EncoderNet):
            raise ValueError(f"EncoderClassifier: network must be an EncoderNet, got {type(network).__name__}")
        self.rest_speed = finite_number(self, "rest_speed", rest_speed, low=0.0)
        # NumPy copies of the weights: one 60-input evaluation per tick costs far less without torch
        state = {k: v.detach().double().numpy() for k, v in network.state_dict().items()}
        self._mean, self._scale = state["mean"], state["scale"]
        self._w1, self._b1 = state["hidden.weight"], state["hidden.bias"]
        self._w2, self._b2 = state["out.weight"][0], float(state["out.bias"][0])
        self.add_input("velocity", Signal(shape=None, unit="mm/s"))
        self.add_input("count", COUNT)
        self.add_output("eps", Signal(unit="1"), initial=math.nan)
        self.add_output("decision", COUNT, initial=UNDECIDED)
        self.add_output("length", COUNT)

    def setup(self) -> None:
        shape = self.velocity.spec.shape
        if len(shape) != 2 or shape[1] != 3:
            raise self._fail(f"velocity must have shape (capacity, 3), got {shape}")

    def classify(self, velocity: np.ndarray) -> tuple[float, int]:
        """ε̂ and the restricted length of a movement given oldest sample first, shape (n, 3)."""
        length = movement_length(velocity, self.rest_speed)
        if length == 0:
            return math.nan, 0
        x = ((resampling_matrix(length) @ velocity[:length]).T.reshape(-1) - self._mean) / self._scale
        z = float(self._w2 @ np.maximum(self._w1 @ x + self._b1, 0.0) + self._b2)
        e = math.exp(-abs(z))  # the sigmoid without overflow for large |z|
        return (1.0 / (1.0 + e) if z >= 0 else e / (1.0 + e)), length

    def output(self, k: int) -> None:
        window = ordered_window(self.velocity.value, int(self.count.value))
        if not plausible(window):
            return
        eps, length = self.classify(window)
        self.eps.value[...] = eps
        self.decision.value[...] = clip_decision(eps)
        self.length.value[...] = length


class PrefixProjection:
    """Running distances between a growing prefix and the same prefix of every library movement.

    ``accumulate`` adds the contribution of new samples to per-movement running sums, so bringing the
    projection up to date costs O(library size × new samples), whatever the elapsed time. Per sample
    the contribution is the Euclidean distance ``‖x(t) − v_d(t)‖`` (``metric="mean"``: the mean
    Euclidean distance over the window, as in the notes and the prototype) or its square
    (``metric="l2"``: the paper's ``dist``, squared). Past the library's length a library movement is
    at rest (zero velocity).

    Parameters
    ----------
    velocity : numpy.ndarray, shape (n, T, 3)
        The library's padded velocities.
    metric : {"mean", "l2"}
    dtype : {"float32", "float64"}
        Precision of the stored library and of the per-sample distances; the running sums are
        float64. ``float32`` halves the memory and is about four times faster on large libraries.
    block : int
        Samples processed per vectorised step (the size of the preallocated work array).
    """

    def __init__(self, velocity: np.ndarray, *, metric: str = "mean", dtype: str = "float32", block: int = 10) -> None:
        self.metric = one_of("PrefixProjection", "metric", metric, ("mean", "l2"))
        dtype = one_of("PrefixProjection", "dtype", dtype, ("float32", "float64"))
        velocity = np.asarray(velocity)
        if velocity.ndim != 3 or velocity.shape[2] != 3:
            raise ValueError(f"PrefixProjection: velocity must have shape (n, T, 3), got {velocity.shape}")
        # time-major (T, 3, n): the rows of one sample are contiguous across the library
        self._library = np.ascontiguousarray(np.transpose(velocity, (1, 2, 0)), dtype=dtype)
        self.size = velocity.shape[0]
        self.max_len = velocity.shape[1]
        self._block = positive_int("PrefixProjection", "block", block)
        self._diff = np.empty((self._block, 3, self.size), dtype=dtype)
        self._dist = np.empty((self._block, self.size), dtype=dtype)

    def accumulate(self, sums: np.ndarray, samples: np.ndarray, start: int) -> None:
        """Add the samples numbered ``start, start + 1, …`` (shape (m, 3)) to ``sums`` (n,) in place."""
        samples = np.asarray(samples)
        for offset in range(0, len(samples), self._block):
            part = samples[offset : offset + self._block]
            t0 = start + offset
            inside = max(0, min(len(part), self.max_len - t0))
            if inside:
                diff, dist = self._diff[:inside], self._dist[:inside]
                np.subtract(self._library[t0 : t0 + inside], part[:inside, :, None], out=diff)
                np.multiply(diff, diff, out=diff)
                np.sum(diff, axis=1, out=dist)
                if self.metric == "mean":
                    np.sqrt(dist, out=dist)
                sums += dist.sum(axis=0, dtype=np.float64)
            if inside < len(part):
                rest = np.einsum("ij,ij->i", part[inside:], part[inside:])
                sums += float(np.sqrt(rest).sum() if self.metric == "mean" else rest.sum())

    def distance(self, sums: np.ndarray, count: int) -> np.ndarray:
        """The distances the sums stand for after ``count`` samples: mean Euclidean, or the L² norm."""
        return sums / max(count, 1) if self.metric == "mean" else np.sqrt(sums)


class LibraryProjector(Block):
    """Online projection of the buffered human movement onto the library's prefixes (section III-B).

    Every ``interval`` samples (when the buffer's ``count`` reaches a multiple of it) the buffered
    prefix is compared with the same prefix of every library movement: the nearest movement of the
    set that does not encode ``e_des`` is η_i, and after the first window the nearest movement of
    the set that does is chosen, once, as the reference ``v_r``. Decisions are taken in the update
    phase, so the decision on samples ``0 … T_i − 1`` shows from tick ``T_i`` on: the first
    ``interval`` ticks have no decision (the blender passes the human signal through).

    The distances are kept as running sums (:class:`PrefixProjection`), so a decision costs
    O(library size × ``interval``).

    Ports
    -----
    velocity : input, shape (capacity, 3), mm/s
        The velocity ring of a :class:`~cogblocks.blocks.buffer.Buffer` (read in the update phase).
    count : input, int64
        Samples received by the buffer (read in the update phase).
    nearest : output, int64
        Library index of η_i; −1 before the first decision.
    reference : output, int64
        Library index of the reference movement; −1 before the first decision.
    v_r : output, shape (3,), mm/s
        The reference's velocity at this tick (zero before the reference is chosen and after its end).
    decisions : output, int64
        Decisions taken so far.
    horizon : output, int64
        The expected end of the altered movement in samples, ``max(length(η_i), length(v_r))``; 0
        before the first decision.

    Parameters
    ----------
    library : ReachLibrary
        The movement library, with its fear labels.
    e_des : {0, 1}
        1: the reference encodes fear (η among the no-fear movements); 0: the roles swap.
    interval : int
        ΔT, samples between two decisions (10).
    metric, dtype : see :class:`PrefixProjection`.
    candidates : array_like of bool, shape (n,), optional
        Library movements the projection may choose (all by default), for instance to leave the
        replayed movement itself out.

    Notes
    -----
    The samples of a decision must still be in the buffer: ``interval`` may not exceed its
    capacity.

    Bad data policy: the buffer upstream replaces non-finite and implausible samples; fed
    directly, an element beyond 1 km/s (:func:`~cogblocks.blocks.samples.plausible`, NaN
    included) counts as that bound with its sign, so the distances stay finite and the decision
    follows the other samples.
    """

    def __init__(
        self,
        library: ReachLibrary,
        *,
        e_des: int = 1,
        interval: int = 10,
        metric: str = "mean",
        dtype: str = "float32",
        candidates: Any = None,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        if not isinstance(library, ReachLibrary):
            raise ValueError(f"LibraryProjector: library must be a ReachLibrary, got {type(library).__name__}")
        self.e_des = one_of(self, "e_des", e_des, (0, 1))
        self.interval = positive_int(self, "interval", interval)
        allowed = np.ones(len(library), dtype=bool) if candidates is None else np.asarray(candidates, dtype=bool)
        if allowed.shape != (len(library),):
            raise ValueError(f"LibraryProjector: candidates must have shape ({len(library)},), got {allowed.shape}")
        self._nearest_set = np.flatnonzero((library.fear != bool(self.e_des)) & allowed)
        self._reference_set = np.flatnonzero((library.fear == bool(self.e_des)) & allowed)
        if self._nearest_set.size == 0 or self._reference_set.size == 0:
            raise ValueError("LibraryProjector: the library needs candidate movements with and without the emotion")
        self.library = library
        self.projection = PrefixProjection(library.velocity, metric=metric, dtype=dtype, block=self.interval)
        self.add_input("velocity", Signal(shape=None, unit="mm/s"), feedthrough=False)
        self.add_input("count", COUNT, feedthrough=False)
        self.add_output("nearest", COUNT, initial=-1)
        self.add_output("reference", COUNT, initial=-1)
        self.add_output("v_r", VELOCITY)
        self.add_output("decisions", COUNT)
        self.add_output("horizon", COUNT)
        self.add_state("sums", np.zeros(len(library)))
        self.add_state("seen", 0)
        self.add_state("n_decisions", 0)
        self.add_state("eta", -1)
        self.add_state("ref", -1)

    def setup(self) -> None:
        shape = self.velocity.spec.shape
        if len(shape) != 2 or shape[1] != 3:
            raise self._fail(f"velocity must have shape (capacity, 3), got {shape}")
        if self.interval > shape[0]:
            raise self._fail(f"interval {self.interval} exceeds the buffer's capacity {shape[0]}")

    def output(self, k: int) -> None:
        t = k // self.every
        self.nearest.value[...] = self.eta
        self.reference.value[...] = self.ref
        self.decisions.value[...] = self.n_decisions
        if self.ref >= 0 and t < self.library.max_len:
            self.v_r.value[...] = self.library.velocity[self.ref, t]
        else:
            self.v_r.value[...] = 0.0
        lengths = self.library.length
        self.horizon.value[...] = max(lengths[self.eta], lengths[self.ref]) if self.eta >= 0 else 0

    def update(self, k: int) -> None:
        count = int(self.count.value)
        if count // self.interval <= self.n_decisions:
            return
        ring = self.velocity.value
        if count - self.seen > len(ring):
            raise self._fail(f"samples {self.seen}…{count - 1} no longer fit the buffer of {len(ring)}")
        rows = np.arange(self.seen, count) % len(ring)
        samples = ring[rows]
        if not plausible(samples):
            samples = np.clip(np.nan_to_num(samples, nan=0.0), -PLAUSIBLE, PLAUSIBLE)
        self.projection.accumulate(self.sums, samples, self.seen)
        self.seen = count
        self.eta = int(self._nearest_set[np.argmin(self.sums[self._nearest_set])])
        if self.ref < 0:
            self.ref = int(self._reference_set[np.argmin(self.sums[self._reference_set])])
        self.n_decisions = count // self.interval


_BLENDING_INPUT_SPECS = {
    "v_h": VELOCITY,
    "v_r": VELOCITY,
    "v_u": VELOCITY,
    "nearest": COUNT,
    "reference": COUNT,
    "decisions": COUNT,
}
#: The ports every blending rule has (:func:`add_blending_ports`).
BLENDING_INPUTS = tuple(_BLENDING_INPUT_SPECS)
BLENDING_OUTPUTS = ("v_a", "c")


def add_blending_ports(block: Block) -> None:
    """Declare the ports every blending rule shares, so that rules swap in the architecture.

    Inputs ``v_h``, ``v_r``, ``v_u`` (zero if unconnected), shape (3,), mm/s, and the projector's
    decision ``nearest``, ``reference``, ``decisions`` (int64); outputs ``v_a`` (mm/s) and ``c``.
    """
    for name, spec in _BLENDING_INPUT_SPECS.items():
        block.add_input(name, spec, default=np.zeros(3) if name == "v_u" else None)
    block.add_output("v_a", VELOCITY)
    block.add_output("c", Signal(unit="1"), initial=1.0)


def blend(c: float, v_h: np.ndarray, v_r: np.ndarray, out: np.ndarray) -> None:
    """``out = c·v_h + (1 − c)·v_r``, in place; ``v_r`` is not read when ``c = 1`` (0·NaN is NaN)."""
    np.multiply(c, v_h, out=out)
    if c != 1.0:
        out += (1.0 - c) * v_r


class VelocityBlender(Block):
    """``v_a = c·v_h + (1 − c)·v_r + v_u`` with ``c = w̃(η_i, v_r)`` from a :class:`SolutionTable`.

    Before the projector's first decision ``c = 1``: the human signal passes through. Afterwards ``c``
    is looked up for the projector's current pair, so it changes only when a decision does.

    Ports
    -----
    v_h : input, shape (3,), mm/s
        The human velocity.
    v_r : input, shape (3,), mm/s
        The reference velocity (from :class:`LibraryProjector`).
    v_u : input, shape (3,), mm/s, optional
        Correction term (zero if unconnected).
    nearest, reference, decisions : input, int64
        The projector's decision.
    v_a : output, shape (3,), mm/s
        The altered velocity.
    c : output, scalar
        The blending coefficient in use.

    Parameters
    ----------
    table : SolutionTable
        w̃ on the projector's library.

    Notes
    -----
    Bad data policy: a non-finite ``v_h`` or ``v_u``, or a non-finite ``v_r`` while it is
    weighted (``c < 1``), gives a non-finite ``v_a`` (:class:`PositionComputer` then holds its
    position); with ``c = 1`` the reference is not used at all.
    """

    def __init__(self, table: SolutionTable, *, period: float | None = None) -> None:
        super().__init__(period=period)
        if not isinstance(table, SolutionTable):
            raise ValueError(f"VelocityBlender: table must be a SolutionTable, got {type(table).__name__}")
        self.table = table
        add_blending_ports(self)

    def output(self, k: int) -> None:
        if int(self.decisions.value) > 0:
            c = self.table.lookup(int(self.nearest.value), int(self.reference.value))
        else:
            c = 1.0
        self.c.value[...] = c
        blend(c, self.v_h.value, self.v_r.value, self.v_a.value)
        self.v_a.value += self.v_u.value


class PositionComputer(Block):
    """Position of the altered movement by integration: ``p_a(t+1) = p_a(t) + dt·v_a(t+1)``, ``p_a(1) = p_h(1)``.

    The update uses the velocity of the new sample, as in the notes; on data that follow eq. (1)
    (``v(t) = (p(t+1) − p(t)) / dt``) the integrated position of an unaltered movement is therefore
    one sample ahead of the recorded one while it moves, and equal to it at rest.

    Ports
    -----
    v : input, shape (3,), mm/s
        The altered velocity v_a.
    p_start : input, shape (3,), mm
        The human position; only its first finite sample is used.
    p : output, shape (3,), mm
        The altered position p_a.

    Notes
    -----
    This is the Amplification position block; the phase-to-position block of section 6.2 is
    :class:`cogblocks.blocks.phase3d.PositionComputer`.

    Bad data policy: a non-finite or implausible (beyond 1 km/s,
    :func:`~cogblocks.blocks.samples.plausible`) velocity holds the position; integration starts
    at the first ``p_start`` that is finite and plausible.
    """

    def __init__(self, *, period: float | None = None) -> None:
        super().__init__(period=period)
        self.add_input("v", VELOCITY)
        self.add_input("p_start", POSITION)
        self.add_output("p", POSITION)
        self.add_state("last", np.zeros(3))
        self.add_state("started", False)

    def output(self, k: int) -> None:
        p = self.p.value
        if not self.started:
            if plausible(self.p_start.value):
                p[...] = self.p_start.value
        elif plausible(self.v.value):
            np.multiply(self.dt, self.v.value, out=p)
            p += self.last
        else:
            p[...] = self.last

    def update(self, k: int) -> None:
        if self.started or plausible(self.p_start.value):
            self.last[...] = self.p.value
            self.started = True
