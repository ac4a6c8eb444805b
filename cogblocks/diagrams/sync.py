"""PoP of Social Connectedness (section 5.2): the L2 architecture in closed loop with a Kuramoto group."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from cogblocks.blocks import Demux, Mux, Probe, Substitute
from cogblocks.data.groups import TABLE2, SyncGroup
from cogblocks.phase import PhaseEstimator
from cogblocks.sim import Block, Diagram, Simulator
from cogblocks.sim.params import one_of
from cogblocks.sync import ArmPositions, Blender, KuramotoGroup, MeanPhaseMotion, MotionComputer, OrderParameter
from cogblocks.sync.l2 import L2Sync

__all__ = ["MOTIONS", "phase_sensing", "plot_sync", "pop_sync", "run_sync"]


def _mean_motion(group: SyncGroup) -> Block:
    return MeanPhaseMotion(group.n, group.assisted)


def _l3_motion(group: SyncGroup, policy: Any) -> Block:
    return MotionComputer(
        policy,
        n=group.n,
        assisted=group.assisted,
        gain=group.gain,
        omega_init=float(np.mean(group.omega)),
        adjacency=group.graph,
    )


def _dqn_motion(group: SyncGroup) -> Block:
    from cogblocks.sync import DQNPolicy

    return _l3_motion(group, DQNPolicy.default())


def _lookahead_motion(group: SyncGroup) -> Block:
    from cogblocks.sync import LookaheadPolicy

    return _l3_motion(group, LookaheadPolicy.for_group(group))


#: Motion computers available by name: each builds a fresh block for a group.
#: ``dqn`` is the trained L3 policy (``python -m cogblocks.training.sync_dqn --seed 0``),
#: ``lookahead`` plans 25 ticks ahead on the group's model (no training), ``mean`` follows
#: the circular mean of the others' phases (no training, no model). Add an entry to make a policy
#: available to :func:`pop_sync`, :func:`run_sync`, the held-out evaluation and the command line.
MOTIONS: dict[str, Callable[[SyncGroup], Block]] = {
    "dqn": _dqn_motion,
    "lookahead": _lookahead_motion,
    "mean": _mean_motion,
}


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

    A hierarchical block (input ``theta``, output ``theta_hat``) standing for
    what a real set-up measures: the L2 architecture then works on estimated
    phases, as it would on a motion-capture stream. ``front_end`` is the
    estimators' option (``"lowpass"`` or ``"kalman"``, see :class:`PhaseEstimator`).
    """
    d = Diagram()
    arms = d.add("arms", ArmPositions(n, amplitude, noise_std=noise_std, seed=seed))
    split = d.add("split", Demux(n))
    join = d.add("join", Mux(n))
    d.connect(arms.p, split.u)
    for i in range(n):
        estimator = d.add(f"estimator{i}", PhaseEstimator(front_end=front_end))
        d.connect(getattr(split, f"y{i}"), estimator.p)
        d.connect(estimator.theta, getattr(join, f"u{i}"))
    d.expose_input("theta", arms.theta)
    d.expose_output("theta_hat", join.y)
    d.expose_output("p", arms.p)
    return d


def pop_sync(
    group: int | SyncGroup = 1,
    l2: bool = True,
    motion: str | Block = "mean",
    blender: Blender | None = None,
    *,
    domain: str = "phase",
    noise_std: float = 1.0,
    seed: int = 0,
    front_end: str = "lowpass",
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
    blender : Blender, optional
        The deliverable's blender by default.
    domain : {"phase", "position"}
        ``"position"`` puts :func:`phase_sensing` (block ``sensing``) between the
        group and the L2 block: the phases drive 1D arm positions (150 mm
        amplitude, ``noise_std`` mm of noise seeded by ``seed``) and the L2
        architecture sees the phases estimated from them. The group and the
        order parameter still use the true phases.
    front_end : {"lowpass", "kalman"}
        What the phase estimators of the ``"position"`` domain put in front of
        Algorithm 1 (see :class:`PhaseEstimator`); unused in the phase domain.
    """
    if domain not in ("phase", "position"):
        raise ValueError(f"pop_sync: domain must be 'phase' or 'position', got {domain!r}")
    one_of("pop_sync", "front_end", front_end, ("lowpass", "kalman"))
    params = _group_of(group)
    d = Diagram()
    assisted = params.assisted if l2 else None
    kuramoto = d.add("group", KuramotoGroup(params.omega, params.gain, adjacency=params.graph, assisted=assisted))
    order = d.add("order", OrderParameter())
    if l2:
        if isinstance(motion, str):
            if motion not in MOTIONS:
                raise ValueError(f"pop_sync: motion must be one of {sorted(MOTIONS)} or a Block, got {motion!r}")
            motion = MOTIONS[motion](params)
        arch = d.add("l2", L2Sync(motion, params.assisted, blender))
        seen = d.add("seen", Substitute(params.assisted))
        d.connect(kuramoto.theta, seen.u)
        if domain == "position":
            sensing = d.add("sensing", phase_sensing(params.n, noise_std=noise_std, seed=seed, front_end=front_end))
            d.connect(kuramoto.theta, sensing.theta)
            d.connect(sensing.theta_hat, arch.theta)
        else:
            d.connect(kuramoto.theta, arch.theta)
        d.connect(arch.theta_l2, kuramoto.theta_l2, seen.v)
        d.connect(seen.y, order.theta)
    else:
        d.connect(kuramoto.theta, order.theta)
    d.add("r", Probe())
    d.connect(order.r, "r.u")
    return d


def _deviation(trace: Any) -> np.ndarray:
    return np.abs(np.angle(np.exp(1j * (trace["theta_l2"] - trace["theta_l0"]))))


def run_sync(group: int | SyncGroup = 1, motions: list[str] | None = None, domain: str = "phase") -> dict[str, Any]:
    """Table 3 for one group: the time-averaged order parameter without and with L2.

    The average is over every sample ``t = 0 … T`` (T/dt + 1 ticks, r(0) = 1), as
    in the deliverable. ``domain="position"`` runs the L2 architecture on
    phases estimated from arm positions (see :func:`pop_sync`).

    Returns
    -------
    dict
        ``{"group", "r_without", "results": [{"policy", "r_with", "change_pct",
        "mean_dev_rad", "max_dev_rad"}, ...]}``; the deviations are
        ``|wrap(θ_L2 − θ_L0)|`` over the run.
    """
    params = _group_of(group)
    motions = list(MOTIONS) if motions is None else motions
    n_steps = round(params.duration / 0.01) + 1
    r_without = float(Simulator(pop_sync(params, l2=False)).run(n_steps=n_steps)["r"].mean())
    results = []
    for name in motions:
        probes = {"theta_l2": "l2.theta_l2", "theta_l0": "l2.theta_l0"}
        sim = Simulator(pop_sync(params, l2=True, motion=name, domain=domain), probes=probes)
        trace = sim.run(n_steps=n_steps)
        r_with = float(trace["r"].mean())
        dev = _deviation(trace)
        results.append(
            {
                "policy": name,
                "r_with": r_with,
                "change_pct": 100.0 * (r_with - r_without) / r_without,
                "mean_dev_rad": float(dev.mean()),
                "max_dev_rad": float(dev.max()),
            }
        )
    number = group if isinstance(group, int) else params.name
    return {"group": number, "domain": domain, "r_without": r_without, "results": results}


def plot_sync(group: int | SyncGroup, motion: str | Block, path: str) -> None:
    """Draw the analogues of Figures 9 and 10: r with and without L2; θ_L0, θ_ref and θ_L2."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    params = _group_of(group)
    n_steps = round(params.duration / 0.01) + 1
    without = Simulator(pop_sync(params, l2=False)).run(n_steps=n_steps)
    probes = {"theta_l2": "l2.theta_l2", "theta_l0": "l2.theta_l0", "theta_ref": "l2.theta_ref"}
    with_l2 = Simulator(pop_sync(params, l2=True, motion=motion), probes=probes).run(n_steps=n_steps)
    label = motion if isinstance(motion, str) else type(motion).__name__
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    ax1.plot(without.t, without["r"], label="without L2", color="0.4")
    ax1.plot(with_l2.t, with_l2["r"], label=f"with L2 ({label})", color="tab:blue")
    ax1.set_ylabel("order parameter r")
    ax1.legend(loc="lower right")
    ax1.set_title(f"{params.name}: Figure 9 and 10 analogues")
    labels = {"theta_l0": ("θ_L0", "k-"), "theta_ref": ("θ_ref", "g--"), "theta_l2": ("θ_L2", "b-")}
    for name, (text, style) in labels.items():
        phase = with_l2[name].copy()
        phase[1:][np.diff(phase) < -np.pi] = np.nan  # break the line where the phase wraps
        ax2.plot(with_l2.t, phase, style, lw=1, label=text)
    ax2.set_ylabel("phase [rad]")
    ax2.set_xlabel("t [s]")
    ax2.legend(loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
