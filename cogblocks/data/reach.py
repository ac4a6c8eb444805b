"""Reach-to-grasp movement library of the PoP of Amplification, and a synthetic generator for it.

The real data set of the appendix paper (11 participants, 458 reach-to-grasp movements, 197 of them
towards a cube paired with an electrical stimulation) is not public. :func:`generate_reach_library`
produces a synthetic stand-in with the same counts, units and layout: minimum-jerk-like reaches with
subject-specific style, and fear-conditioned reaches that are slower and more cautious by an amount
that differs between subjects. ``docs/data-reach.md`` lists the facts from the literature the model
relies on and which effect sizes are our own assumptions.

Coordinates are in mm in a table frame: x to the participant's right, y forward (away from the
body), z up; the start position is near the origin. Velocities are in mm/s, sampled every ``dt`` s.
Every movement is stored padded to ``max_len`` samples: velocity with zeros, position by holding the
last position. Velocity and position satisfy eq. (1) of the appendix paper, ``v(t) = (p(t+1) - p(t)) / dt``,
for every ``t < length - 1`` (and trivially in the padding); the last sample of a movement keeps the
residual speed of a still hand (a few mm/s), which the held position does not follow.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.special import beta as beta_function
from scipy.special import betainc

from cogblocks.sim.timing import BASE_STEP

__all__ = ["ReachLibrary", "generate_reach_library"]


@dataclass
class ReachLibrary:
    """A library of labelled reach-to-grasp movements, padded to a common length.

    Attributes
    ----------
    velocity : numpy.ndarray, shape (n, max_len, 3)
        Wrist velocity in mm/s; zero after each movement's end.
    position : numpy.ndarray, shape (n, max_len, 3)
        Wrist position in mm; holds the last position after each movement's end.
    length : numpy.ndarray of int, shape (n,)
        Number of samples of each movement, in ``1 .. max_len``.
    fear : numpy.ndarray of bool, shape (n,)
        True for a movement that encodes fear (reach towards the stimulation-paired cube).
    subject : numpy.ndarray of int, shape (n,)
        Participant index (0-based).
    target : numpy.ndarray of int, shape (n,)
        Cube reached for: 0 (left) or 1 (right); -1 when the source does not say (real data).
    dt : float
        Sampling time in seconds (0.01 s: 100 Hz motion capture).

    Raises
    ------
    ValueError
        If the arrays have inconsistent shapes or invalid values; the message names the field.
    """

    velocity: np.ndarray
    position: np.ndarray
    length: np.ndarray
    fear: np.ndarray
    subject: np.ndarray
    target: np.ndarray
    dt: float = BASE_STEP

    def __post_init__(self) -> None:
        self.velocity = np.asarray(self.velocity, dtype=np.float64)
        self.position = np.asarray(self.position, dtype=np.float64)
        if self.velocity.ndim != 3 or self.velocity.shape[2] != 3:
            raise ValueError(f"velocity must have shape (n, max_len, 3), got {self.velocity.shape}")
        n, max_len, _ = self.velocity.shape
        if max_len < 1:
            raise ValueError("velocity must have at least one sample per movement (max_len >= 1)")
        if self.position.shape != self.velocity.shape:
            raise ValueError(f"position must have shape {self.velocity.shape} like velocity, got {self.position.shape}")
        if not np.all(np.isfinite(self.velocity)):
            raise ValueError("velocity contains NaN or infinite values")
        if not np.all(np.isfinite(self.position)):
            raise ValueError("position contains NaN or infinite values")
        self.length = _integer_labels("length", self.length, n)
        if np.any((self.length < 1) | (self.length > max_len)):
            bad = int(np.flatnonzero((self.length < 1) | (self.length > max_len))[0])
            raise ValueError(f"length must be in 1..{max_len}, got {self.length[bad]} for movement {bad}")
        fear = _integer_labels("fear", self.fear, n)
        if np.any((fear != 0) & (fear != 1)):
            raise ValueError("fear must hold booleans (0 or 1)")
        self.fear = fear.astype(bool)
        self.subject = _integer_labels("subject", self.subject, n)
        if np.any(self.subject < 0):
            raise ValueError("subject must hold non-negative indices")
        self.target = _integer_labels("target", self.target, n)
        if np.any((self.target < -1) | (self.target > 1)):
            raise ValueError("target must be 0, 1 or -1 (unknown)")
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt must be a positive finite number of seconds, got {self.dt!r}")
        self.dt = float(self.dt)

    def __len__(self) -> int:
        return self.velocity.shape[0]

    @property
    def max_len(self) -> int:
        """Padded number of samples per movement."""
        return self.velocity.shape[1]

    def subset(self, indices: np.ndarray) -> ReachLibrary:
        """Return a new library with the selected movements (copies).

        Parameters
        ----------
        indices : array_like of int or bool
            Movement indices, or a boolean mask of length ``len(self)``.

        Returns
        -------
        ReachLibrary
            The selected movements, in the order given.
        """
        idx = np.asarray(indices)
        if idx.dtype != bool:
            idx = idx.astype(np.intp)
        return ReachLibrary(
            velocity=self.velocity[idx].copy(),
            position=self.position[idx].copy(),
            length=self.length[idx].copy(),
            fear=self.fear[idx].copy(),
            subject=self.subject[idx].copy(),
            target=self.target[idx].copy(),
            dt=self.dt,
        )

    def split(self, val_fraction: float = 0.3, seed: int | np.random.Generator = 0) -> tuple[np.ndarray, np.ndarray]:
        """Split the movement indices into training and validation sets, stratified by the fear label.

        In each class, ``round(val_fraction * class size)`` movements chosen at random go to
        validation and the rest to training.

        Parameters
        ----------
        val_fraction : float
            Share of each class held out for validation, in (0, 1).
        seed : int or numpy.random.Generator
            Seed of the random selection; the same seed gives the same split.

        Returns
        -------
        train, val : numpy.ndarray of int
            Sorted, disjoint indices that together cover every movement.
        """
        if not 0.0 < val_fraction < 1.0:
            raise ValueError(f"val_fraction must be in (0, 1), got {val_fraction!r}")
        rng = np.random.default_rng(seed)
        val_parts = []
        for label in (False, True):
            members = np.flatnonzero(self.fear == label)
            n_val = int(round(val_fraction * members.size))
            val_parts.append(rng.permutation(members)[:n_val])
        val = np.sort(np.concatenate(val_parts))
        train = np.setdiff1d(np.arange(len(self)), val)
        return train, val

    def restricted(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """Position and velocity of movement ``i`` cut to its own length (copies).

        Returns
        -------
        position, velocity : numpy.ndarray, shape (length[i], 3)
        """
        n = self.length[i]
        return self.position[i, :n].copy(), self.velocity[i, :n].copy()


def _integer_labels(name: str, values: np.ndarray, n: int) -> np.ndarray:
    """Check that ``values`` is one integer per movement and return it as an int64 array."""
    array = np.asarray(values)
    if array.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},), one value per movement, got {array.shape}")
    if array.dtype == bool:
        return array.astype(np.int64)
    if not np.issubdtype(array.dtype, np.number) or not np.all(np.isfinite(array)) or np.any(array != np.round(array)):
        raise ValueError(f"{name} must hold integers")
    return array.astype(np.int64)


# --- Synthetic generator ---------------------------------------------------------------------------
#
# Every number below is a modelling assumption tuned so that the data look like table-top reaches
# (about 30 cm, 0.6-1.4 s, peak speeds of a few hundred mm/s) and so that fear is decodable but not
# trivially: a 60-input MLP reaches roughly 80-90 % validation accuracy (see docs/data-reach.md).

_CUBE_SPACING_MM = 170.0  # lateral distance between the two cube centres
_MIN_DURATION_S = 0.5
_MAX_DURATION_S = 1.8  # the longest movement must fit in max_len samples
_BASELINE_SHARE = 0.4  # share of the no-fear movements recorded before any stimulation (both cubes)
_PROFILE_CONCENTRATION = 6.0  # a + b of the Beta speed profile; a = b = 3 is exactly minimum jerk


@dataclass(frozen=True)
class _SubjectStyle:
    """How one simulated participant reaches when not afraid, and how strongly fear changes it."""

    start: np.ndarray  # mean start position, mm
    depth: float  # forward distance of the cubes, mm
    height: float  # grasp height relative to the start, mm
    duration: float  # mean movement time without fear, s
    peak_fraction: float  # time of peak speed as a fraction of the main transport
    approach_share: float  # share of the distance covered by the final grasp-approach submovement
    approach_time: float  # share of the movement time spent mostly in the approach phase
    curvature: float  # signed lateral deviation of the path, as a fraction of the distance
    lift: float  # vertical arc above the straight line, mm
    variability: float  # scale of the trial-to-trial variability
    fear_sensitivity: float  # 0: fear leaves the movement unchanged; ~1: a strong effect
    fear_target: int  # cube paired with the stimulation (counterbalanced across subjects)


def generate_reach_library(
    seed: int | np.random.Generator = 0,
    n_subjects: int = 11,
    n_fear: int = 197,
    n_no_fear: int = 261,
    max_len: int = 200,
    dt: float = BASE_STEP,
) -> ReachLibrary:
    """Generate a synthetic reach-to-grasp library with fear and no-fear movements.

    Each participant reaches from a start position to one of two cubes about 30 cm ahead and 17 cm
    apart. A movement is a main transport submovement followed by an overlapping grasp-approach
    submovement (both minimum-jerk-like), with a curved path, a small vertical lift and smooth,
    speed-dependent sensor noise. Fear movements (towards the stimulation-paired cube) are slower,
    decelerate for longer, have a larger approach phase and vary more, by a subject-specific amount.
    The model movement starts and ends at rest; with the noise, the first and last samples keep a residual
    speed of a few mm/s, as a motion-capture marker does on a still hand.

    Parameters
    ----------
    seed : int or numpy.random.Generator
        Seed of every random choice; the same seed gives identical data.
    n_subjects : int
        Number of participants (at least 1).
    n_fear, n_no_fear : int
        Number of fear and no-fear movements (non-negative, not both zero). They are spread over the
        subjects roughly evenly.
    max_len : int
        Padded number of samples; must cover the longest movement (1.8 s).
    dt : float
        Sampling time in seconds.

    Returns
    -------
    ReachLibrary
        Movements ordered by subject; within a subject, baseline movements come first.

    Raises
    ------
    ValueError
        If a parameter is out of range; the message names it, its value and what is allowed.
    """
    _check_int("n_subjects", n_subjects, minimum=1)
    _check_int("n_fear", n_fear, minimum=0)
    _check_int("n_no_fear", n_no_fear, minimum=0)
    if n_fear + n_no_fear < 1:
        raise ValueError(f"n_fear + n_no_fear must be at least 1, got n_fear={n_fear}, n_no_fear={n_no_fear}")
    if isinstance(dt, bool) or not isinstance(dt, (int, float)) or not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a positive number of seconds, got dt={dt!r}")
    _check_int("max_len", max_len, minimum=1)
    needed = int(np.ceil(_MAX_DURATION_S / dt - 1e-9)) + 1
    if max_len < needed:
        raise ValueError(
            f"max_len={max_len} with dt={dt} s cannot hold the longest movement ({_MAX_DURATION_S} s): "
            f"max_len must be at least {needed}"
        )

    rng = np.random.default_rng(seed)
    styles = [_draw_subject_style(rng, s) for s in range(n_subjects)]
    # Roughly even spread: real sessions lose a few trials each, so allow +/-10 % per subject.
    weights = 1.0 + rng.uniform(-0.1, 0.1, n_subjects)
    fear_counts = _apportion(n_fear, weights)
    no_fear_counts = _apportion(n_no_fear, weights)

    velocity = np.zeros((n_fear + n_no_fear, max_len, 3))
    position = np.zeros_like(velocity)
    length = np.zeros(n_fear + n_no_fear, dtype=np.int64)
    fear = np.zeros(n_fear + n_no_fear, dtype=bool)
    subject = np.zeros(n_fear + n_no_fear, dtype=np.int64)
    target = np.zeros(n_fear + n_no_fear, dtype=np.int64)

    row = 0
    for s, style in enumerate(styles):
        for is_fear, cube in _session_trials(rng, style, fear_counts[s], no_fear_counts[s]):
            v, p = _synthesize_movement(rng, style, cube, is_fear, dt)
            n = v.shape[0]
            velocity[row, :n] = v
            position[row, :n] = p
            position[row, n:] = p[-1]
            length[row], fear[row], subject[row], target[row] = n, is_fear, s, cube
            row += 1
    return ReachLibrary(velocity, position, length, fear, subject, target, dt=float(dt))


def _check_int(name: str, value: object, minimum: int) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {name}={value!r}")


def _apportion(total: int, weights: np.ndarray) -> np.ndarray:
    """Split ``total`` into integer parts proportional to ``weights`` (largest remainder method)."""
    exact = total * weights / weights.sum()
    counts = np.floor(exact).astype(np.int64)
    remainder = exact - counts
    counts[np.argsort(-remainder, kind="stable")[: total - counts.sum()]] += 1
    return counts


def _draw_subject_style(rng: np.random.Generator, index: int) -> _SubjectStyle:
    # One participant in eleven did not recognise the cube-stimulus pairing (appendix paper, V-A):
    # subjects 0, 11, 22, ... get almost no fear effect.
    if index % 11 == 0:
        sensitivity = rng.uniform(0.0, 0.1)
    else:
        sensitivity = rng.uniform(0.35, 1.2)
    return _SubjectStyle(
        start=rng.normal(0.0, [6.0, 6.0, 4.0]),
        depth=rng.uniform(290.0, 310.0),
        height=rng.uniform(15.0, 35.0),
        duration=rng.uniform(0.75, 1.0),
        peak_fraction=rng.uniform(0.40, 0.50),
        approach_share=rng.uniform(0.03, 0.07),
        approach_time=rng.uniform(0.12, 0.22),
        curvature=rng.uniform(-0.06, 0.06),
        lift=rng.uniform(15.0, 45.0),
        variability=rng.uniform(0.8, 1.2),
        fear_sensitivity=sensitivity,
        fear_target=int(index % 2),
    )


def _session_trials(
    rng: np.random.Generator, style: _SubjectStyle, n_fear: int, n_no_fear: int
) -> list[tuple[bool, int]]:
    """(fear, target) of one subject's movements: baseline first, then conditioned trials shuffled.

    Baseline reaches (before any stimulation) go to either cube and count as no fear; afterwards,
    reaches to the paired cube are fear movements and reaches to the other cube are not.
    """
    n_baseline = int(round(_BASELINE_SHARE * n_no_fear))
    baseline = [(False, int(cube)) for cube in rng.integers(0, 2, n_baseline)]
    conditioned = [(True, style.fear_target)] * n_fear + [(False, 1 - style.fear_target)] * (n_no_fear - n_baseline)
    order = rng.permutation(len(conditioned))
    return baseline + [conditioned[k] for k in order]


def _synthesize_movement(
    rng: np.random.Generator, style: _SubjectStyle, cube: int, is_fear: bool, dt: float
) -> tuple[np.ndarray, np.ndarray]:
    """Velocity and position (each (T, 3)) of one movement, starting and ending (almost) at rest."""
    jitter = style.variability
    # Fear strength of this trial: the subject's sensitivity, varying from trial to trial, so that
    # some fear trials look like no-fear ones.
    effect = style.fear_sensitivity * rng.uniform(0.3, 1.5) if is_fear else 0.0
    jitter *= 1.0 + 0.4 * effect

    duration = style.duration * (1.0 + 0.33 * effect) * np.exp(rng.normal(0.0, 0.09 * jitter))
    duration = float(np.clip(duration, _MIN_DURATION_S, _MAX_DURATION_S))
    n_samples = int(round(duration / dt)) + 1
    time = np.arange(n_samples) * dt
    duration = time[-1]

    peak_fraction = np.clip(style.peak_fraction - 0.08 * effect + rng.normal(0.0, 0.03 * jitter), 0.28, 0.6)
    approach_share = np.clip(style.approach_share + 0.04 * effect + rng.normal(0.0, 0.015 * jitter), 0.0, 0.25)
    approach_time = np.clip(style.approach_time + 0.08 * effect + rng.normal(0.0, 0.03 * jitter), 0.1, 0.45)

    start = style.start + rng.normal(0.0, 3.0, 3)
    goal = np.array([(cube - 0.5) * _CUBE_SPACING_MM, style.depth, style.height]) + rng.normal(0.0, 5.0, 3)
    displacement = goal - start
    distance = np.linalg.norm(displacement)
    horizontal = np.array([displacement[0], displacement[1], 0.0])
    lateral = np.array([-horizontal[1], horizontal[0], 0.0]) / np.linalg.norm(horizontal)

    # Main transport: a Beta-shaped speed profile (minimum jerk when the peak is at mid-time) that
    # ends when the approach submovement, which overlaps its tail, takes over.
    main_duration = duration * (1.0 - approach_time)
    a = 1.0 + (_PROFILE_CONCENTRATION - 2.0) * peak_fraction
    b = _PROFILE_CONCENTRATION - a
    main_progress, main_rate = _beta_submovement(time, 0.0, main_duration, a, b)
    approach_onset = 0.7 * main_duration
    _, approach_rate = _beta_submovement(time, approach_onset, duration, 3.0, 3.0)

    velocity = np.outer(main_rate * (1.0 - approach_share) + approach_rate * approach_share, displacement)
    # Curved, lifted path: bell-shaped offsets 4 s (1 - s) of the main progress s vanish, with their
    # velocity, at both ends of the movement.
    curvature = style.curvature + rng.normal(0.0, 0.015 * jitter)
    lift = style.lift + rng.normal(0.0, 5.0 * jitter)
    bell_rate = 4.0 * (1.0 - 2.0 * main_progress) * main_rate
    velocity += np.outer(bell_rate * curvature * distance, lateral) + np.outer(bell_rate * lift, [0.0, 0.0, 1.0])

    velocity += _sensor_noise(rng, velocity, jitter)
    position = start + np.concatenate([np.zeros((1, 3)), np.cumsum(velocity[:-1] * dt, axis=0)])
    # Recompute the velocity from the stored positions so that eq. (1) holds to the last bit.
    velocity[:-1] = np.diff(position, axis=0) / dt
    return velocity, position


def _beta_submovement(time: np.ndarray, onset: float, end: float, a: float, b: float) -> tuple[np.ndarray, np.ndarray]:
    """Progress (0 to 1) and its rate (1/s) of a submovement with a Beta(a, b)-shaped speed profile."""
    u = np.clip((time - onset) / (end - onset), 0.0, 1.0)
    progress = betainc(a, b, u)
    rate = u ** (a - 1.0) * (1.0 - u) ** (b - 1.0) / beta_function(a, b) / (end - onset)
    return progress, rate


def _sensor_noise(rng: np.random.Generator, velocity: np.ndarray, jitter: float) -> np.ndarray:
    """Smooth velocity noise: a floor of 1.5 mm/s per axis plus a part proportional to the speed."""
    n = velocity.shape[0]
    white = rng.normal(0.0, 1.0, (n, 3))
    smooth = gaussian_filter1d(white, sigma=2.0, axis=0, mode="nearest")
    smooth /= smooth.std()
    speed = np.linalg.norm(velocity, axis=1, keepdims=True)
    return smooth * (1.5 + 0.03 * jitter * speed)
