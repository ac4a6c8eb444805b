"""PoP of Amplification (section 5.1 and the appendix paper): the L2 architecture replaying human movements.

:class:`L2Amplification` is the online architecture as one block: a :class:`Buffer` of the human
movement, the :class:`LibraryProjector`, the blending rule, a corrector and the
:class:`~cogblocks.amplification.VelocityPositionComputer`. :func:`pop_amplification` replays one movement
through it and classifies the altered movement online; :func:`run_amplification` gives the paper's
validation figures on the held-out no-fear movements of the synthetic library."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from cogblocks.amplification import (
    Buffer,
    CorrectorNet,
    EncoderClassifier,
    EncoderNet,
    NoCorrection,
    RLCorrector,
    SolutionTable,
    load_corrector,
    load_encoder,
    solution_table,
)
from cogblocks.amplification.judges import Judges
from cogblocks.amplification.l2 import L2Amplification
from cogblocks.blocks import Playback, Probe
from cogblocks.data.reach import ReachLibrary
from cogblocks.diagrams.amplification_setup import (
    OPTIMISED,
    STEP_LIMIT,
    AmplificationSetup,
    amplification_judges,
    amplification_setup,
    judged_shares,
    optimised_subspace,
)
from cogblocks.diagrams.amplification_setup import blender_networks as shipped_blender_networks
from cogblocks.diagrams.naturalness import movement_naturalness
from cogblocks.diagrams.tracking import SMOOTHING_HZ, add_kalman_front_end, checked_cutoff
from cogblocks.sim import Block, Diagram, Simulator, Trace
from cogblocks.sim.params import finite_number, one_of

__all__ = [
    "AmplificationSetup",
    "PAPER",
    "SMOOTHING_HZ",
    "STEP_LIMIT",
    "amplification_judges",
    "amplification_setup",
    "plot_amplification",
    "pop_amplification",
    "replay_movement",
    "run_amplification",
]

#: The appendix paper's validation figures (65 real no-fear movements; the distance only without RL).
PAPER = {
    "blend": {"encoded": 0.89, "terminal_ok": 0.24, "final_distance_mm": 31.0, "n": 65},
    "blend_rl": {"encoded": 0.65, "terminal_ok": 0.90, "final_distance_mm": None, "n": 65},
}

DELTA_POS_MM = 20.0  # terminal constraint (13c)


def pop_amplification(
    movement: tuple[np.ndarray, np.ndarray],
    library: ReachLibrary | None = None,
    *,
    table: SolutionTable | None = None,
    encoder: EncoderNet | None = None,
    corrector: Block | None = None,
    blending: Block | None = None,
    e_des: int = 1,
    front_end: str = "recorded",
    noise_mm: float = 0.0,
    seed: int = 0,
    smoothing_hz: float | str | None = SMOOTHING_HZ,
    step_limit: float | None = STEP_LIMIT,
) -> Diagram:
    """A ready diagram replaying one human movement through the L2 architecture.

    Blocks: ``human_v`` and ``human_p`` (:class:`Playback` of the velocity, zero after its end, and
    of the position, held), ``l2`` (:class:`L2Amplification`), ``altered`` (a :class:`Buffer` of the
    altered movement) and ``encoder`` (an :class:`EncoderClassifier` of it); probes ``v_h``, ``p_h``,
    ``v_a``, ``p_a``, ``v_r``, ``c`` and ``eps``.

    Parameters
    ----------
    movement : (velocity, position)
        Arrays of shape (T, 3) in mm/s and mm, one row per 10 ms tick.
    library : ReachLibrary, optional
        The library the projector searches; by default the training part of
        :func:`amplification_setup` (with its ``table`` and ``encoder``).
    table : SolutionTable, optional
        w̃ on ``library``; computed (and cached) with ``encoder`` if not given.
    encoder : EncoderNet, optional
        The classifier of the altered movement; the shipped one by default.
    corrector : Block, optional
        :class:`~cogblocks.amplification.NoCorrection` (default) or an :class:`~cogblocks.amplification.RLCorrector`.
    blending : Block, optional
        A blending rule replacing the :class:`VelocityBlender`.
    e_des : {0, 1}
        1: encode fear; 0: remove it.
    front_end : {"recorded", "kalman"}
        ``"recorded"`` feeds the recorded velocity and position; ``"kalman"`` plays only the tracked
        positions (plus ``noise_mm`` of white noise, seeded by ``seed``) through a 3D
        :class:`~cogblocks.sensing.KalmanEstimator` (block ``tracking``) whose position and
        velocity estimates feed the architecture, as on a live motion-capture stream. Without noise
        its frozen-sample detection is off (an exactly repeated resting position is a still hand).
    smoothing_hz : float, "auto" or None
        With ``front_end="kalman"``: the cut-off (Hz) of a low-pass on the estimated velocity (block ``smooth``;
        ``"auto"``: the least smoothing that keeps a still hand's estimate within 12 mm/s, at most 3 Hz),
        followed by a :class:`~cogblocks.sensing.RestGate` (block ``still``) set at the speed a still hand's
        estimate shows at ``noise_mm``, so that the tracker's noise is not emitted and the hand is seen to stop
        (:mod:`cogblocks.diagrams.tracking`); ``None``: the estimate as it is.
    step_limit : float, optional
        Limit the altered velocity's per-tick step to this multiple of the human's largest so far
        (:class:`~cogblocks.amplification.smoothing.VelocityStepLimiter`, block ``l2.limiter``). The default,
        :data:`~cogblocks.diagrams.amplification_setup.STEP_LIMIT` (1), keeps every step within the human's own;
        None: the blending rule's output as it is (the deliverable's architecture).
    """
    one_of("pop_amplification", "front_end", front_end, ("recorded", "kalman"))
    noise_mm = finite_number("pop_amplification", "noise_mm", noise_mm, low=0.0)
    velocity, position = (np.asarray(a, dtype=np.float64) for a in movement)
    if velocity.ndim != 2 or velocity.shape[1] != 3 or position.shape != velocity.shape:
        raise ValueError(
            f"pop_amplification: movement must be (velocity, position) of equal shapes (T, 3), "
            f"got {velocity.shape} and {position.shape}"
        )
    if library is None:
        setup = amplification_setup(None, e_des)
        library, table = setup.movements, setup.table if table is None else table
        encoder = setup.encoder if encoder is None else encoder
    encoder = load_encoder() if encoder is None else encoder
    table = solution_table(encoder, library, e_des) if table is None else table
    smoothing_hz = checked_cutoff("pop_amplification", smoothing_hz, library.dt)
    d = Diagram()
    human_v = d.add("human_v", Playback(velocity, unit="mm/s", at_end="zero"))
    human_p = d.add("human_p", Playback(position, unit="mm", at_end="hold"))
    l2 = d.add("l2", L2Amplification(
        library, table, corrector=corrector, blending=blending, e_des=e_des, capacity=library.max_len,
        step_limit=step_limit,
    ))  # fmt: skip
    altered = d.add("altered", Buffer(library.max_len))
    classifier = d.add("encoder", EncoderClassifier(encoder))
    if front_end == "kalman":
        p_hat, v_hat = add_kalman_front_end(d, position, noise_mm, seed, smoothing_hz, library.dt)
        d.connect(v_hat, l2.v_h)
        d.connect(p_hat, l2.p_h)
    else:
        d.connect(human_v.y, l2.v_h)
        d.connect(human_p.y, l2.p_h)
    d.connect(l2.v_a, altered.v)
    d.connect(l2.p_a, altered.p)
    d.connect(altered.velocity, classifier.velocity)
    d.connect(altered.count, classifier.count)
    probed = (("v_h", human_v.y), ("p_h", human_p.y), ("v_a", l2.v_a), ("p_a", l2.p_a), ("v_r", l2.v_r))
    for name, source in (*probed, ("c", l2.c), ("eps", classifier.eps)):
        d.add(name, Probe())
        d.connect(source, f"{name}.u")
    return d


def replay_movement(
    setup: AmplificationSetup,
    human: int,
    blending: Block | None = None,
    probes: dict[str, str] | None = None,
    **options: Any,
) -> Trace:
    """Movement ``human`` of ``setup``'s library through :func:`pop_amplification`, over the library's window.

    The projector searches ``setup.movements`` with ``setup.table`` and ``setup.encoder``, toward ``setup.e_des``;
    ``blending`` (e.g. an :class:`~cogblocks.amplification.OptimalBlender`) replaces the table's blend, ``probes``
    adds probed signals to the trace, and ``options`` go to :func:`pop_amplification` (``corrector``, ...).
    """
    velocity, position = setup.library.velocity[human], setup.library.position[human]
    d = pop_amplification(
        (velocity, position), setup.movements, table=setup.table, encoder=setup.encoder, blending=blending,
        e_des=setup.e_des, **options,
    )  # fmt: skip
    return Simulator(d, probes=probes).run(n_steps=setup.library.max_len)


def _corrector_factories(network: CorrectorNet | None) -> dict[str, Callable[[], Block]]:
    return {
        "blend": NoCorrection,
        "blend_rl": lambda: RLCorrector(network if network is not None else load_corrector()),
    }


def run_amplification(
    variants: Sequence[str] = ("blend", "blend_rl", "optimised"),
    seed: int | None = None,
    *,
    limit: int | None = None,
    e_des: int = 1,
    front_end: str = "recorded",
    noise_mm: float = 0.0,
    smoothing_hz: float | str | None = SMOOTHING_HZ,
    step_limit: float | None = STEP_LIMIT,
    setup: AmplificationSetup | None = None,
    judges: Judges | None = None,
    blender_networks: Sequence[EncoderNet] | None = None,
    corrector: CorrectorNet | None = None,
    optimised: Mapping[str, Any] | None = None,
) -> dict[str, dict[str, Any]]:
    """Replay every validation movement that does not encode ``e_des`` through the online architecture.

    Each movement is replayed over the library's padded window (200 samples: the human and, without
    correction, the altered movement have stopped by its end). The altered movement is classified by
    the shipped encoder with the clipping rule; its final position is compared with the human's.

    Parameters
    ----------
    variants : sequence of {"blend", "blend_rl", "optimised"}
        Blending alone, blending with the RL corrector, and the optimisation-based blending
        (:class:`~cogblocks.amplification.OptimalBlender` configured as :data:`OPTIMISED`, with the
        setup's subspace; without corrector).
    seed : int, optional
        Seed of the 70/30 split; by default the encoder's own validation split (see
        :func:`amplification_setup`).
    limit : int, optional
        Replay only the first ``limit`` movements (smoke tests).
    e_des : {0, 1}
        1: make no-fear movements encode fear; 0: remove fear from fear movements.
    front_end, noise_mm, smoothing_hz, step_limit : see :func:`pop_amplification` (movement ``i``: noise seed ``i``).
    setup : AmplificationSetup, optional
        Another library, split, encoder and w̃ (:func:`cogblocks.training.pipeline.run_pipeline`);
        then ``judges`` and ``blender_networks`` must be given too.
    judges : Judges, optional
        The independent judges; by default :func:`amplification_judges` (shipped split only).
    blender_networks : sequence of EncoderNet, optional
        The ensemble the optimised variant constrains; by default the shipped encoder and
        ``encoder_ensemble.pt``.
    corrector : CorrectorNet, optional
        The RL corrector's network; the shipped one by default.
    optimised : mapping, optional
        Keyword arguments of the optimised blender instead of :data:`OPTIMISED` (without
        ``components``: the subspace is the setup's).

    Returns
    -------
    dict
        Per variant: ``encoded`` (share decided as ``e_des`` by the encoder), ``terminal_ok`` (share
        whose final position is within 20 mm of the human's), ``final_distance_mm`` (mean) and ``n``;
        for ``"optimised"`` also ``solve_ms_p50`` and ``solve_ms_p99`` (CPU time, ms, of everything the
        block does for a decision in one tick: building, solving, checking; with a single-tick solve,
        the time per decision), ``decision_ms_p50`` and ``decision_ms_p99`` (the sum over a
        decision's ticks), ``solve_ticks`` (ticks that worked on a decision), ``fallbacks`` (decisions
        that kept the previous plan or the table's blend) and ``decisions`` (decisions that ran the
        solver). Judged independently: ``judges`` (share each judge decides
        as ``e_des``), ``encoded_independent`` (the ensemble judge's share) and ``judges_agreement``
        (share of movements on which the two judges agree whether ``e_des`` is encoded). ``naturalness``: the
        altered velocity against the human's (:func:`~cogblocks.diagrams.naturalness.movement_naturalness`).
    """
    if setup is None:
        if seed is not None and judges is None:
            raise ValueError(
                "run_amplification: the shipped judges belong to the shipped split; with a seed pass judges"
            )
        setup = amplification_setup(seed, e_des)
        judges = amplification_judges() if judges is None else judges
        if blender_networks is None:
            blender_networks = shipped_blender_networks(setup.encoder)
    elif judges is None or blender_networks is None:
        raise ValueError("run_amplification: with a setup, pass its judges and blender_networks")
    factories = _corrector_factories(corrector)
    unknown = [v for v in variants if v not in (*factories, "optimised")]
    if unknown:
        raise ValueError(
            f"run_amplification: unknown variant(s) {unknown}; choose from {sorted([*factories, 'optimised'])}"
        )
    humans = setup.humans if limit is None else setup.humans[:limit]
    n_steps = setup.library.max_len
    results = {}
    for variant in variants:
        encoded, distances, solve_ms, tick_ms, fallbacks, altered = [], [], [], [], 0, []
        for index in humans:
            blender = _optimal_blender(setup, blender_networks, optimised) if variant == "optimised" else None
            d = pop_amplification(
                (setup.library.velocity[index], setup.library.position[index]),
                setup.movements,
                table=setup.table,
                encoder=setup.encoder,
                corrector=NoCorrection() if blender is not None else factories[variant](),
                blending=blender,
                e_des=e_des,
                front_end=front_end,
                noise_mm=noise_mm,
                seed=int(index),
                smoothing_hz=smoothing_hz,
                step_limit=step_limit,
            )
            trace = Simulator(d, probes={"decision": "encoder.decision"}).run(n_steps=n_steps)
            encoded.append(int(trace["decision"][-1]) == e_des)
            distances.append(float(np.linalg.norm(trace["p_a"][-1] - trace["p_h"][-1])))
            altered.append(trace["v_a"])
            if blender is not None:
                solve_ms.extend(blender.solve_ms)
                tick_ms.extend(blender.tick_ms)
                fallbacks += blender.fallbacks
        distances_mm = np.array(distances)
        results[variant] = {
            "encoded": float(np.mean(encoded)) if encoded else float("nan"),
            "terminal_ok": float(np.mean(distances_mm <= DELTA_POS_MM)) if distances else float("nan"),
            "final_distance_mm": float(distances_mm.mean()) if distances else float("nan"),
            "n": len(humans),
            **judged_shares(judges, altered, e_des),
            "naturalness": movement_naturalness(altered, setup.library.velocity[humans], setup.library.dt)
            if altered
            else {},
        }
        if variant == "optimised":
            p50, p99 = np.percentile(tick_ms, [50, 99]) if tick_ms else (float("nan"), float("nan"))
            d50, d99 = np.percentile(solve_ms, [50, 99]) if solve_ms else (float("nan"), float("nan"))
            results[variant].update(
                solve_ms_p50=float(p50), solve_ms_p99=float(p99), fallbacks=fallbacks, decisions=len(solve_ms),
                decision_ms_p50=float(d50), decision_ms_p99=float(d99), solve_ticks=len(tick_ms),
            )  # fmt: skip
    return results


def _optimal_blender(
    setup: AmplificationSetup, networks: Sequence[EncoderNet], options: Mapping[str, Any] | None = None
) -> Block:
    # imported here: casadi (about 0.1 s to import) is loaded only when the optimised variant is asked for
    from cogblocks.amplification import OptimalBlender

    subspace = setup.subspace if setup.subspace is not None else optimised_subspace(setup.movements, setup.e_des)
    if options is None:
        options = {k: v for k, v in OPTIMISED.items() if k != "components"}
    return OptimalBlender(setup.movements, list(networks), setup.table, e_des=setup.e_des, subspace=subspace, **options)


def plot_amplification(path: str, index: int | None = None, variant: str = "blend", seed: int | None = None) -> None:
    """Draw the analogue of the paper's Figure 6 for one validation movement.

    Three panels with ``v_h`` (red), the reference ``v_r`` (green) and ``v_a`` (blue) per axis, and
    ``c(t)``.

    Parameters
    ----------
    path : str
        Output file (png, pdf, svg).
    index : int, optional
        Which validation movement (position in :attr:`AmplificationSetup.humans`); by default the
        first one the architecture makes encode fear, as the paper's representative example.
    variant : {"blend", "blend_rl"}
    seed : int, optional
        Seed of the split, as in :func:`run_amplification`.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    setup = amplification_setup(seed, 1)
    factories = _corrector_factories(None)
    one_of("plot_amplification", "variant", variant, tuple(factories))
    candidates = setup.humans if index is None else setup.humans[index : index + 1]
    for human in candidates:
        d = pop_amplification(
            (setup.library.velocity[human], setup.library.position[human]),
            setup.movements,
            table=setup.table,
            encoder=setup.encoder,
            corrector=factories[variant](),
        )
        probes = {"reference": "l2.reference", "decision": "encoder.decision"}
        trace = Simulator(d, probes=probes).run(n_steps=setup.library.max_len)
        if trace["decision"][-1] == 1:
            break
    reference = int(trace["reference"][-1])
    end = int(max(setup.library.length[human], setup.movements.length[reference]))
    t = trace.t[:end]
    fig, axes = plt.subplots(4, 1, figsize=(8, 8), sharex=True)
    for axis, name in enumerate("xyz"):
        ax = axes[axis]
        ax.plot(t, trace["v_h"][:end, axis], color="tab:red", label="$v_h$ (human, no fear)")
        ax.plot(t, setup.movements.velocity[reference, :end, axis], color="tab:green", label="$v_r$ (reference, fear)")
        ax.plot(t, trace["v_a"][:end, axis], color="tab:blue", label="$v_a$ (altered)")
        ax.set_ylabel(f"$v_{name}$ [mm/s]")
    axes[0].legend(loc="lower right", fontsize=8)
    axes[0].set_title(
        f"Figure 6 analogue (synthetic data): movement {int(human)}, {variant}, final ε̂ {trace['eps'][-1]:.2f}"
    )
    axes[3].step(t, trace["c"][:end], where="post", color="k")
    axes[3].set_ylim(-0.05, 1.05)
    axes[3].set_ylabel("c")
    axes[3].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
