"""PoP of Social Connectedness (section 5.2): the L2 architecture in closed loop with a Kuramoto group."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from dataclasses import replace
from typing import Any

import numpy as np

from cogblocks.blocks import Demux, Mux, Probe, Substitute
from cogblocks.blocks.angles import wrap_pi
from cogblocks.data.groups import TABLE2, SyncGroup
from cogblocks.diagrams.naturalness import sync_naturalness
from cogblocks.diagrams.sync_motions import DEFAULT_MOTION, DEFAULT_MOTIONS, MOTIONS
from cogblocks.phase import PhaseEstimator
from cogblocks.sim import BASE_STEP, Block, Diagram, Simulator, Trace
from cogblocks.sim.params import finite_number, one_of
from cogblocks.sync import ArmPositions, Blender, KuramotoGroup, OrderParameter
from cogblocks.sync.blending import SLEW, BlenderParams, blender_params
from cogblocks.sync.handover import SettledHandover
from cogblocks.sync.l2 import L2Sync

__all__ = [
    "DEFAULT_BLENDER",
    "DEFAULT_MOTION",
    "DEFAULT_MOTIONS",
    "MOTIONS",
    "phase_sensing",
    "plot_sync",
    "pop_sync",
    "run_sync",
    "simulate",
    "sync_table",
]

#: The blender the ready diagrams use when none is given: the continuous one, whose avatar never jumps
#: (``"deliverable"`` is the deliverable's exact law, which flips the alteration at ±π).
DEFAULT_BLENDER = "continuous"

_LONG_RUN = 20_000  # ticks from which a run in a terminal shows a progress bar, as the Simulator's default


def _group_of(group: int | SyncGroup) -> SyncGroup:
    if isinstance(group, SyncGroup):
        return group
    if group not in TABLE2:
        raise ValueError(f"pop_sync: group must be one of {sorted(TABLE2)} or a SyncGroup, got {group!r}")
    return TABLE2[group]


def phase_sensing(
    n: int, amplitude: float = 150.0, noise_std: float = 1.0, seed: int = 0, front_end: str = "lowpass"
) -> Diagram:
    """Phases → 1D arm positions → one :class:`PhaseEstimator` per participant → estimated phases.

    A hierarchical block (input ``theta``, outputs ``theta_hat`` and each estimate's ``settled``) standing for
    what a real set-up measures: the L2 architecture then works on estimated
    phases, as it would on a motion-capture stream. ``front_end`` is the
    estimators' option (``"lowpass"`` or ``"kalman"``, see :class:`PhaseEstimator`).
    """
    d = Diagram()
    arms = d.add("arms", ArmPositions(n, amplitude, noise_std=noise_std, seed=seed))
    split = d.add("split", Demux(n))
    join = d.add("join", Mux(n))
    settled = d.add("settled", Mux(n))
    d.connect(arms.p, split.u)
    for i in range(n):
        estimator = d.add(f"estimator{i}", PhaseEstimator(front_end=front_end))
        d.connect(getattr(split, f"y{i}"), estimator.p)
        d.connect(estimator.theta, getattr(join, f"u{i}"))
        d.connect(estimator.settled, getattr(settled, f"u{i}"))
    d.expose_input("theta", arms.theta)
    d.expose_output("theta_hat", join.y)
    d.expose_output("settled", settled.y)
    d.expose_output("p", arms.p)
    return d


def pop_sync(
    group: int | SyncGroup = 1,
    l2: bool = True,
    motion: str | Block = DEFAULT_MOTION,
    blender: str | BlenderParams | Block | None = DEFAULT_BLENDER,
    *,
    domain: str = "phase",
    noise_std: float = 1.0,
    seed: int = 0,
    front_end: str = "lowpass",
    handover: bool = True,
) -> Diagram:
    """A ready closed-loop diagram of the PoP of Social Connectedness.

    Blocks: ``group`` (:class:`KuramotoGroup`), and with ``l2=True`` the
    :class:`L2Sync` block ``l2`` whose θ_L2 replaces the assisted participant's
    phase in everyone's coupling and in what is measured (``seen``); ``order``
    computes the order parameter, recorded by the probe ``r``.

    Parameters
    ----------
    group : int or SyncGroup
        Table 2's group number (1, 2, 3) or custom parameters, on any graph
        (``SyncGroup.graph``: ring, all-to-all, random or a weighted matrix).
    l2 : bool
        Include the L2 architecture.
    motion : str or Block
        A name from :data:`MOTIONS` or a motion computer block.
    blender : str, BlenderParams, Block or None
        ``"continuous"`` (the default: :data:`~cogblocks.sync.blending.CONTINUOUS`, the avatar never jumps),
        ``"deliverable"`` or ``None`` (the deliverable's exact blender), a
        :class:`~cogblocks.sync.blending.BlenderParams`, or a blender block (a :class:`Blender`, say). A motion
        computer that predicts plans through it.
    domain : {"phase", "position"}
        ``"position"`` puts :func:`phase_sensing` (block ``sensing``) between the
        group and the L2 block: the phases drive 1D arm positions (150 mm
        amplitude, ``noise_std`` mm of noise seeded by ``seed``) and the L2
        architecture sees the phases estimated from them. The group and the
        order parameter still use the true phases.
    front_end : {"lowpass", "kalman"}
        What the phase estimators of the ``"position"`` domain put in front of
        Algorithm 1 (see :class:`PhaseEstimator`); unused in the phase domain.
    handover : bool
        In the ``"position"`` domain, a :class:`~cogblocks.sync.handover.SettledHandover` block ``avatar``
        shows the person's own movement until the assisted participant's estimate has settled, then hands
        over to θ_L2 (an avatar drawn from an unsettled estimate jumps); ``False`` shows θ_L2 from the start.
    """
    if domain not in ("phase", "position"):
        raise ValueError(f"pop_sync: domain must be 'phase' or 'position', got {domain!r}")
    one_of("pop_sync", "front_end", front_end, ("lowpass", "kalman"))
    params = _group_of(group)
    d = Diagram()
    kuramoto = d.add("group", KuramotoGroup.for_group(params, assisted=l2))
    order = d.add("order", OrderParameter())
    if l2:
        if isinstance(motion, str):
            if motion not in MOTIONS:
                raise ValueError(f"pop_sync: motion must be one of {sorted(MOTIONS)} or a Block, got {motion!r}")
            motion = MOTIONS[motion](params)
        if not isinstance(blender, Block):
            blender = Blender(params=blender_params("pop_sync", blender))
        arch = d.add("l2", L2Sync(motion, params.assisted, blender))
        seen = d.add("seen", Substitute(params.assisted))
        d.connect(kuramoto.theta, seen.u)
        shown = arch.theta_l2
        if domain == "position":
            sensing = d.add("sensing", phase_sensing(params.n, noise_std=noise_std, seed=seed, front_end=front_end))
            d.connect(kuramoto.theta, sensing.theta)
            d.connect(sensing.theta_hat, arch.theta)
            if handover:
                slew = getattr(getattr(blender, "params", None), "slew", None) or SLEW  # as fast as an alteration
                avatar = d.add("avatar", SettledHandover(params.n, params.assisted, slew=slew))
                d.connect(kuramoto.theta, avatar.theta)
                d.connect(arch.theta_l2, avatar.theta_l2)
                d.connect(sensing.settled, avatar.settled)
                shown = avatar.theta_avatar
        else:
            d.connect(kuramoto.theta, arch.theta)
        d.connect(shown, kuramoto.theta_l2, seen.v)
        d.connect(seen.y, order.theta)
    else:
        d.connect(kuramoto.theta, order.theta)
    d.add("r", Probe())
    d.connect(order.r, "r.u")
    return d


def simulate(
    diagram: Diagram, n_steps: int, probes: dict[str, str] | None = None, *, label: str, progress: bool | None = None
) -> Trace:
    """Run ``diagram`` for ``n_steps`` ticks under a progress bar named ``label``.

    ``progress=None`` shows the bar as the :class:`Simulator` would (long runs, standard error a
    terminal, ``CI`` unset); the name tells which of several runs the bar belongs to. The run is
    the same, tick for tick, with or without the bar.
    """
    sim = Simulator(diagram, probes=probes, progress=False)
    if progress is None:
        progress = n_steps >= _LONG_RUN and sys.stderr.isatty() and not os.environ.get("CI")
    if not progress:
        return sim.run(n_steps=n_steps)
    from tqdm import tqdm

    parts = []
    chunk = max(1000, n_steps // 200)
    with tqdm(total=n_steps, unit="tick", desc=label, leave=False) as bar:
        for start in range(0, n_steps, chunk):
            parts.append(sim.run(n_steps=min(chunk, n_steps - start)))
            bar.update(len(parts[-1].t))
    signals = {name: np.concatenate([part[name] for part in parts]) for name in parts[0]}
    return Trace(np.concatenate([part.t for part in parts]), signals, parts[0].units)


def _checked(group: int | SyncGroup, motions: list[str] | None, duration: float | None) -> tuple[SyncGroup, list]:
    """The group's parameters (with ``duration`` if given) and the motion computers, checked before any run."""
    params = _group_of(group)
    if duration is not None:
        params = replace(params, duration=finite_number("run_sync", "duration", duration, low=0.0, low_open=True))
    motions = list(DEFAULT_MOTIONS) if motions is None else list(motions)
    unknown = [name for name in motions if isinstance(name, str) and name not in MOTIONS]
    if unknown:
        raise ValueError(f"run_sync: unknown motion computer(s) {unknown}; known: {sorted(MOTIONS)}")
    return params, motions


def sync_table(
    group: int | SyncGroup = 1,
    motions: list[str] | None = None,
    domain: str = "phase",
    *,
    duration: float | None = None,
    seed: int = 0,
    progress: bool | None = None,
    blender: str | BlenderParams | None = DEFAULT_BLENDER,
    handover: bool = True,
) -> Iterator[dict[str, Any]]:
    """Table 3 for one group, one figure as soon as it is computed (see :func:`run_sync`).

    Yields first ``{"group", "domain", "r_without"}``, then one row ``{"policy", "r_with",
    "change_pct", "mean_dev_rad", "max_dev_rad", "max_step_rad", "jumps_per_min", "peak_speed_ratio"}``
    per motion computer (the position domain adds ``position_peak_speed_ratio`` and
    ``position_rms_jerk_ratio``; see :mod:`cogblocks.diagrams.naturalness`; a motion computer with a ``world``,
    :class:`~cogblocks.sync.GatedMotion`, adds ``"world"``, what it believed at the end of the run). Progress
    bars are named after the group and the run (``progress`` as in :func:`simulate`); ``blender`` and
    ``handover`` as in :func:`pop_sync`.
    """
    params, motions = _checked(group, motions, duration)
    number = group if isinstance(group, int) else params.name
    n_steps = round(params.duration / BASE_STEP) + 1
    without = simulate(pop_sync(params, l2=False), n_steps, label=f"group {number}, without L2", progress=progress)
    r_without = float(without["r"].mean())
    yield {"group": number, "domain": domain, "r_without": r_without}
    for name in motions:
        probes = {"theta_l2": "l2.theta_l2", "theta_l0": "l2.theta_l0", "theta": "group.theta"}
        diagram = pop_sync(params, l2=True, motion=name, blender=blender, domain=domain, seed=seed, handover=handover)
        if domain == "position":
            probes["avatar"] = "avatar.theta_avatar" if "avatar" in diagram.blocks else "l2.theta_l2"
        label = f"group {number}, L2 with {name if isinstance(name, str) else type(name).__name__}"
        trace = simulate(diagram, n_steps, probes, label=label, progress=progress)
        r_with = float(trace["r"].mean())
        dev = np.abs(wrap_pi(trace["theta_l2"] - trace["theta_l0"]))
        row = {
            "policy": name,
            "r_with": r_with,
            "change_pct": 100.0 * (r_with - r_without) / r_without,
            "mean_dev_rad": float(dev.mean()),
            "max_dev_rad": float(dev.max()),
            **sync_naturalness(trace, params.assisted if domain == "position" else None),
        }
        world = getattr(diagram["l2.motion"], "world", None)
        if world is not None:  # a motion computer that tells which world it found itself in (GatedMotion)
            row["world"] = world
        yield row


def run_sync(
    group: int | SyncGroup = 1,
    motions: list[str] | None = None,
    domain: str = "phase",
    *,
    duration: float | None = None,
    seed: int = 0,
    progress: bool | None = None,
    blender: str | BlenderParams | None = DEFAULT_BLENDER,
    handover: bool = True,
) -> dict[str, Any]:
    """Table 3 for one group: the time-averaged order parameter without and with L2.

    The average is over every sample ``t = 0 … T`` (T/dt + 1 ticks, r(0) = 1), as
    in the deliverable. ``domain="position"`` runs the L2 architecture on
    phases estimated from arm positions (see :func:`pop_sync`), with sensor noise
    seeded by ``seed``. ``duration`` (seconds) replaces the group's T; ``blender`` and ``handover`` are
    :func:`pop_sync`'s (``"deliverable"`` for the deliverable's exact blender). Every motion
    computer name is checked before the first run.

    Returns
    -------
    dict
        ``{"group", "domain", "r_without", "results": [{"policy", "r_with", "change_pct",
        "mean_dev_rad", "max_dev_rad", ...naturalness}, ...]}``; the deviations are
        ``|wrap(θ_L2 − θ_L0)|`` over the run, the naturalness keys as in :func:`sync_table`.
    """
    options = {"duration": duration, "seed": seed, "progress": progress, "blender": blender, "handover": handover}
    head, *rows = sync_table(group, motions, domain, **options)
    return {**head, "results": rows}


def plot_sync(
    group: int | SyncGroup,
    motion: str | Block,
    path: str,
    *,
    duration: float | None = None,
    window: float = 10.0,
    domain: str = "phase",
    seed: int = 0,
    blender: str | BlenderParams | None = DEFAULT_BLENDER,
    handover: bool = True,
) -> None:
    """Draw the analogues of Figures 9 and 10 and save them to ``path``.

    Top: r with and without L2 over the whole run. Middle: the phase differences
    wrap(θ_ref − θ_L0) and wrap(θ_L2 − θ_L0) over the whole run (bounded, unlike the phases
    themselves). Bottom: θ_L0, θ_ref and θ_L2 over the last ``window`` seconds (at most a quarter
    of the run; shaded above), where the wrapped phases can be told apart. ``domain``, ``seed``, ``blender`` and
    ``handover`` are :func:`pop_sync`'s.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    params, _ = _checked(group, [motion], duration)
    label = motion if isinstance(motion, str) else type(motion).__name__
    n_steps = round(params.duration / BASE_STEP) + 1
    without = simulate(pop_sync(params, l2=False), n_steps, label="plot, without L2")
    probes = {"theta_l2": "l2.theta_l2", "theta_l0": "l2.theta_l0", "theta_ref": "l2.theta_ref"}
    diagram = pop_sync(params, l2=True, motion=motion, blender=blender, domain=domain, seed=seed, handover=handover)
    with_l2 = simulate(diagram, n_steps, probes, label=f"plot, L2 with {label}")
    t = with_l2.t
    zoom = t >= t[-1] - min(window, t[-1] / 4)  # a short run is zoomed too
    fig, (ax1, ax2, ax3) = plt.subplots(3, 1, figsize=(9, 8.5))
    ax1.plot(without.t, without["r"], label="without L2", color="0.4", lw=1)
    ax1.plot(t, with_l2["r"], label=f"with L2 ({label})", color="tab:blue", lw=1)
    ax1.set_ylabel("order parameter r")
    ax1.legend(loc="lower right")
    ax1.set_title(f"{params.name}: Figures 9 and 10 analogues ({domain} domain)")
    for name, text, style in (("theta_ref", "θ_ref − θ_L0", "g-"), ("theta_l2", "θ_L2 − θ_L0", "b-")):
        difference = wrap_pi(with_l2[name] - with_l2["theta_l0"])
        difference[1:][np.abs(np.diff(difference)) > np.pi] = np.nan  # no vertical line where it wraps
        ax2.plot(t, difference, style, lw=0.8, label=text)
    ax2.set_ylim(-np.pi, np.pi)
    ax2.set_yticks([-np.pi, -np.pi / 2, 0, np.pi / 2, np.pi], ["−π", "−π/2", "0", "π/2", "π"])
    ax2.set_ylabel("phase difference [rad]")
    ax2.legend(loc="upper right")
    for ax in (ax1, ax2):
        if not zoom.all():
            ax.axvspan(t[zoom][0], t[-1], color="0.9", zorder=0)
        ax.set_xlim(t[0], t[-1])
    for name, text, style in (("theta_l0", "θ_L0", "k-"), ("theta_ref", "θ_ref", "g--"), ("theta_l2", "θ_L2", "b-")):
        phase = with_l2[name][zoom].copy()
        phase[1:][np.diff(phase) < -np.pi] = np.nan  # break the line where the phase wraps
        ax3.plot(t[zoom], phase, style, lw=1.2, label=text)
    ax3.set_ylabel("phase [rad]")
    ax3.set_xlabel("t [s]")
    ax3.set_title(f"the last {t[-1] - t[zoom][0]:g} s", fontsize="medium", loc="left")
    ax3.legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), ncols=3, frameon=False)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
