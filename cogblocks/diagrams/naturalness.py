"""How natural the avatar's motion is: jumps, peak speed and jerk of the altered motion against the person's.

The deliverable asks that the avatar's movements stay "as similar as possible to those of the assisted
participant". These pure NumPy functions measure it from recorded traces, beside every gain:

- phase domain (PoP of Social Connectedness): :func:`phase_naturalness` from θ_L2 and θ_L0;
- position domain: :func:`position_naturalness` from the avatar's and the person's positions;
- PoP of Amplification: :func:`movement_naturalness` from the altered and the human velocity.

Every ratio is the avatar's figure over the person's, so 1 means "moves like the person".
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from cogblocks.sim.timing import BASE_STEP

__all__ = [
    "JUMP_RAD",
    "alteration_steps",
    "movement_naturalness",
    "naturalness_text",
    "phase_naturalness",
    "phase_speed",
    "position_naturalness",
    "sync_naturalness",
]

#: A tick whose change of wrap_π(θ_L2 − θ_L0) exceeds this is a jump: over a 10 ms tick the avatar then
#: runs more than 5 rad/s faster or slower than the person.
JUMP_RAD = 0.05


def _wrap(x: np.ndarray) -> np.ndarray:
    return np.mod(np.asarray(x, dtype=float) + np.pi, 2.0 * np.pi) - np.pi


def _phases(theta: Any, name: str) -> np.ndarray:
    theta = np.asarray(theta, dtype=float)
    if theta.ndim != 1 or theta.size < 2 or not np.all(np.isfinite(theta)):
        raise ValueError(f"naturalness: {name} must be a finite 1D trace of at least 2 ticks, got shape {theta.shape}")
    return theta


def alteration_steps(theta_l2: Any, theta_l0: Any) -> np.ndarray:
    """Per-tick change of the alteration wrap_π(θ_L2 − θ_L0), in rad (one value fewer than the traces).

    The change itself is wrapped too: the alteration passing from just below π to just above −π is a small
    change, not a jump of 2π.
    """
    theta_l2, theta_l0 = _phases(theta_l2, "theta_l2"), _phases(theta_l0, "theta_l0")
    if theta_l2.shape != theta_l0.shape:
        raise ValueError(f"naturalness: theta_l2 {theta_l2.shape} and theta_l0 {theta_l0.shape} differ in length")
    return np.abs(_wrap(np.diff(_wrap(theta_l2 - theta_l0))))


def phase_speed(theta: Any, dt: float = BASE_STEP) -> np.ndarray:
    """Phase speed per tick, rad/s: the unwrapped phase's difference over ``dt`` (one value fewer)."""
    return np.abs(_wrap(np.diff(_phases(theta, "theta")))) / dt


def phase_naturalness(theta_l2: Any, theta_l0: Any, dt: float = BASE_STEP, jump: float = JUMP_RAD) -> dict[str, float]:
    """The avatar's phase against the person's.

    Parameters
    ----------
    theta_l2, theta_l0 : array_like
        The avatar's phase θ_L2 and the assisted participant's θ_L0, one value per tick (rad, wrapped or not).
    dt : float
        The tick, s.
    jump : float
        The change of the alteration in one tick (rad) counted as a jump.

    Returns
    -------
    dict
        ``max_step_rad`` (largest per-tick change of wrap_π(θ_L2 − θ_L0)), ``jumps_per_min`` (ticks whose change
        exceeds ``jump``, per minute of trace) and ``peak_speed_ratio`` (the avatar's peak phase speed over the
        person's). θ_L2 = θ_L0 gives 0, 0 and 1.
    """
    steps = alteration_steps(theta_l2, theta_l0)
    minutes = steps.size * dt / 60.0
    person = phase_speed(theta_l0, dt).max()
    return {
        "max_step_rad": float(steps.max()),
        "jumps_per_min": float(np.count_nonzero(steps > jump) / minutes),
        "peak_speed_ratio": float(phase_speed(theta_l2, dt).max() / person) if person > 0 else float("nan"),
    }


def _derivatives(x: Any, dt: float, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    x = np.asarray(x, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2 or x.shape[0] < 4 or not np.all(np.isfinite(x)):
        raise ValueError(f"naturalness: {name} must be a finite (ticks[, axes]) trace of >= 4 ticks, got {x.shape}")
    v = np.diff(x, axis=0) / dt
    a = np.diff(v, axis=0) / dt
    return v, a, np.diff(a, axis=0) / dt


def _norm(x: np.ndarray) -> np.ndarray:
    return np.linalg.norm(x, axis=1)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(x**2, axis=1))))


def _ratio(a: float, b: float) -> float:
    return a / b if b > 0 else float("nan")


def position_naturalness(p_avatar: Any, p_person: Any, dt: float = BASE_STEP) -> dict[str, float]:
    """The avatar's position against the person's (1D or (ticks, axes) traces, any unit of length).

    Velocity, acceleration and jerk are the first, second and third differences over ``dt``.

    Returns
    -------
    dict
        ``position_peak_speed_ratio`` (peak speed of the avatar over the person's) and
        ``position_rms_jerk_ratio`` (RMS of the jerk's norm, the same way round).
    """
    va, _, ja = _derivatives(p_avatar, dt, "p_avatar")
    vp, _, jp = _derivatives(p_person, dt, "p_person")
    return {
        "position_peak_speed_ratio": float(_ratio(_norm(va).max(), _norm(vp).max())),
        "position_rms_jerk_ratio": float(_ratio(_rms(ja), _rms(jp))),
    }


def _velocity_figures(v: np.ndarray, dt: float) -> tuple[float, float, float]:
    """Largest per-tick velocity step, peak acceleration (central second difference of position) and RMS jerk."""
    step = np.diff(v, axis=0)
    jerk = np.diff(step, axis=0) / dt**2
    return float(_norm(step).max()), float(_norm(step).max() / dt), _rms(jerk)


def movement_naturalness(altered: Sequence[Any], human: Sequence[Any], dt: float = BASE_STEP) -> dict[str, Any]:
    """The altered movements' velocity against the human movements' they were made from (PoP of Amplification).

    Parameters
    ----------
    altered, human : sequence of array_like
        One (ticks, axes) velocity trace per movement, pairwise of equal shape (mm/s).
    dt : float
        The sampling step, s.

    Returns
    -------
    dict
        Per movement the altered movement's figure over its human's: ``velocity_step_ratio`` (largest per-tick
        change of the velocity vector), ``peak_accel_ratio`` (peak acceleration norm; with accelerations as the
        velocity's differences over ``dt`` it equals the step ratio) and ``rms_jerk_ratio``; each summarised over
        the movements as ``{"median", "max"}``. Also ``steps_within_share`` (share of movements whose altered
        largest step is at most the human's, to 1e-9 of it) and the medians of the raw figures,
        ``altered_step_mm_s`` and ``human_step_mm_s``.
    """
    if len(altered) != len(human) or not altered:
        raise ValueError(
            f"naturalness: need as many altered as human movements (>= 1), got {len(altered)}, {len(human)}"
        )
    rows = []
    for a, h in zip(altered, human, strict=True):
        (sa, aa, ja), (sh, ah, jh) = (_velocity_figures(np.asarray(x, dtype=float), dt) for x in (a, h))
        rows.append((sa, sh, _ratio(sa, sh), _ratio(aa, ah), _ratio(ja, jh)))
    table = np.array(rows)

    def summary(column: np.ndarray) -> dict[str, float]:
        return {"median": float(np.median(column)), "max": float(np.max(column))}

    return {
        "velocity_step_ratio": summary(table[:, 2]),
        "peak_accel_ratio": summary(table[:, 3]),
        "rms_jerk_ratio": summary(table[:, 4]),
        # a step limited to the human's largest equals it up to rounding: compare to 1e-9 of it
        "steps_within_share": float(np.mean(table[:, 0] <= table[:, 1] * (1.0 + 1e-9))),
        "altered_step_mm_s": float(np.median(table[:, 0])),
        "human_step_mm_s": float(np.median(table[:, 1])),
    }


def sync_naturalness(trace: Any, assisted: int | None = None, amplitude: float = 150.0) -> dict[str, float]:
    """:func:`phase_naturalness` of a run of ``pop_sync`` probed at ``theta_l2`` and ``theta_l0``: the alteration.

    With ``assisted`` and probes ``theta`` of the group's true phases and ``avatar`` of the phase the avatar
    shows (the position domain) also :func:`position_naturalness` of the avatar's arm ``amplitude · cos θ_avatar``
    against the assisted person's ``amplitude · cos θ`` (noise-free: sensor noise is not the person's movement),
    which shows what the phase estimate adds to the alteration.
    """
    dt = float(trace.t[1] - trace.t[0]) if len(trace.t) > 1 else BASE_STEP
    figures = phase_naturalness(trace["theta_l2"], trace["theta_l0"], dt)
    if assisted is not None:
        person = amplitude * np.cos(np.asarray(trace["theta"])[:, assisted])
        figures.update(position_naturalness(amplitude * np.cos(trace["avatar"]), person, dt))
    return figures


def naturalness_text(row: dict[str, Any]) -> str:
    """One line of the naturalness figures of a :func:`~cogblocks.diagrams.sync.sync_table` row, for the terminal."""
    text = (
        f"largest step {row['max_step_rad']:.3f} rad, {row['jumps_per_min']:.0f} jumps/min, "
        f"peak phase speed {row['peak_speed_ratio']:.2f}x the person's"
    )
    if "position_peak_speed_ratio" in row:
        text += (
            f"; arm peak speed {row['position_peak_speed_ratio']:.2f}x, RMS jerk {row['position_rms_jerk_ratio']:.1f}x"
        )
    return text
