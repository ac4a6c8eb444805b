"""Ready live diagrams: an LSL stream in, a cognitive architecture, an LSL stream out (``cogblocks live``)."""

from __future__ import annotations

from typing import Any

from cogblocks.data.groups import TABLE2, SyncGroup
from cogblocks.diagrams.sync import DEFAULT_BLENDER, MOTIONS
from cogblocks.live.inlet import LSLInlet
from cogblocks.live.outlet import LSLOutlet
from cogblocks.phase import PhaseEstimator
from cogblocks.sensing import L1, KalmanEstimator
from cogblocks.sim import Block, Diagram
from cogblocks.sync import Blender, L2Sync, OrderParameter
from cogblocks.sync.blending import blender_params

__all__ = ["LAG", "LIVE_DIAGRAMS", "live_diagram", "live_l1", "live_motion", "live_phase", "live_sync"]

#: How far back the inlets read a stream: a 100 Hz sample period plus transport and jitter, so that
#: two received samples surround the time read and the blocks see the stream on a regular grid.
LAG = 0.02


def _wire(arch: Block, port_in: str, port_out: str, inlet: LSLInlet, outlet: LSLOutlet) -> Diagram:
    """inlet → arch → outlet, exposing the architecture's output, the inlet's sample, age and freshness."""
    d = Diagram()
    d.add("inlet", inlet)
    d.add("arch", arch)
    d.add("outlet", outlet)
    d.connect(inlet.y, getattr(arch, port_in))
    d.connect(getattr(arch, port_out), outlet.u)
    d.expose_output(port_out, getattr(arch, port_out))
    d.expose_output("sample", inlet.y)
    d.expose_output("age_ms", inlet.age_ms)
    d.expose_output("fresh", inlet.fresh)
    return d


def live_phase(
    in_stream: str, out_stream: str, *, unit: str = "mm", source_unit: str | None = None, timeout: float = 5.0
) -> Diagram:
    """A 1-channel position stream in, its phase (:class:`~cogblocks.phase.PhaseEstimator`) out.

    The inlet resamples the stream :data:`LAG` s back on the tick grid (converting a stream in m or cm
    to ``unit``; ``source_unit`` is the unit of a stream that declares none); the output stream (type
    ``"Phase"``) carries ``theta`` in rad, wrapped to ``[0, 2π)``.
    """
    inlet = LSLInlet(in_stream, unit=unit, source_unit=source_unit, mode="interpolate", lag=LAG, timeout=timeout)
    return _wire(PhaseEstimator(unit=unit), "p", "theta", inlet, LSLOutlet(out_stream, stream_type="Phase"))


def live_motion(name: str, group: SyncGroup) -> Block:
    """The motion computer ``name`` of :data:`MOTIONS` for a live run of ``group``, of no fixed length.

    ``replan`` decides on a worker thread (a decision does not fit a 10 ms tick) and plans ``horizon`` ahead
    without a trial end; ``gated`` is that threaded planner behind a :class:`~cogblocks.sync.GatedMotion`, as
    :data:`MOTIONS` gates its own; every other name is built as :data:`MOTIONS` builds it.
    """
    if name not in MOTIONS:
        raise ValueError(f"live_motion: name must be one of {sorted(MOTIONS)}, got {name!r}")
    if name in ("replan", "gated"):
        from cogblocks.sync import GatedMotion, RecedingPlanMotion

        planner = RecedingPlanMotion(group.n, group.assisted, adjacency=group.graph, end=None, worker="thread")
        return planner if name == "replan" else GatedMotion(planner)
    return MOTIONS[name](group)


def live_sync(
    in_stream: str,
    out_stream: str,
    *,
    group: int = 1,
    motion: str = "dqn",
    timeout: float = 5.0,
    blender: str = DEFAULT_BLENDER,
) -> Diagram:
    """The participants' phases in (one channel each, rad), the avatar's phase θ_L2 out.

    The L2 architecture of the PoP of Social Connectedness (:class:`~cogblocks.sync.L2Sync`)
    for a group of Table 2 (its size fixes the channel count) with the motion computer ``motion``
    (a name of :data:`~cogblocks.diagrams.sync.MOTIONS`, built by :func:`live_motion`;
    the trained DQN policy by default), behind ``blender`` (``"continuous"``, whose avatar never jumps, or
    ``"deliverable"``, the deliverable's exact blender). The inlet resamples the phases :data:`LAG` s back on the
    tick grid, along the circle. Besides ``theta_l2`` and the inlet's ``sample``, ``age_ms`` and ``fresh``, the
    diagram shows ``theta_l0`` (the assisted participant's phase), the blending's ``lam`` and ``r``, the order
    parameter of the participants' phases as received.
    """
    if group not in TABLE2:
        raise ValueError(f"live_sync: group must be one of {sorted(TABLE2)}, got {group!r}")
    params = TABLE2[group]
    if motion not in MOTIONS:
        raise ValueError(f"live_sync: motion must be one of {sorted(MOTIONS)}, got {motion!r}")
    arch = L2Sync(live_motion(motion, params), params.assisted, Blender(params=blender_params("live_sync", blender)))
    inlet = LSLInlet(
        in_stream, shape=(params.n,), unit="rad", wrapped=True, mode="interpolate", lag=LAG, timeout=timeout
    )
    d = _wire(arch, "theta", "theta_l2", inlet, LSLOutlet(out_stream, stream_type="Phase"))
    order = d.add("order", OrderParameter())
    d.connect(inlet.y, order.theta)
    d.expose_output("theta_l0", arch.theta_l0)
    d.expose_output("lam", arch.lam)
    d.expose_output("r", order.r)
    return d


def live_l1(
    in_stream: str,
    out_stream: str,
    *,
    delay: float = 0.1,
    unit: str = "mm",
    source_unit: str | None = None,
    timeout: float = 5.0,
) -> Diagram:
    """A 3-channel marker stream in, the L1 avatar's delay-compensated 3D position out.

    ``delay`` is how late the stream's samples arrive. The inlet resamples the stream ``delay`` +
    :data:`LAG` s back on the tick grid, and :class:`~cogblocks.sensing.L1` (a constant-acceleration
    Kalman filter on three axes) predicts that far ahead; the output stream (type ``"MoCap"``) has
    channels ``x``, ``y``, ``z``. ``unit`` and ``source_unit`` are as in :func:`live_phase`.
    """
    arch = L1(delay + LAG, estimator=KalmanEstimator("ca", dims=3, unit=unit))
    inlet = LSLInlet(
        in_stream, shape=(3,), unit=unit, source_unit=source_unit, mode="interpolate", lag=delay + LAG, timeout=timeout
    )
    outlet = LSLOutlet(out_stream, stream_type="MoCap", channel_names=["x", "y", "z"])
    return _wire(arch, "p", "p_avatar", inlet, outlet)


#: The ready live diagrams by the name ``cogblocks live`` gives them.
LIVE_DIAGRAMS = {"phase": live_phase, "sync": live_sync, "l1": live_l1}


def live_diagram(options: dict[str, Any]) -> Diagram:
    """The ready diagram that ``options`` describe, as a session file keeps them.

    Keys: ``diagram`` (a name of :data:`LIVE_DIAGRAMS`), ``in`` and ``out`` (stream names), and as they
    apply ``timeout``, ``group``, ``policy`` and ``blender`` (sync), ``delay`` (l1), ``unit`` (the input's unit when the
    stream declares none; phase and l1).
    """
    name = options.get("diagram")
    if name not in LIVE_DIAGRAMS:
        raise ValueError(f"live_diagram: diagram must be one of {sorted(LIVE_DIAGRAMS)}, got {name!r}")
    kw: dict[str, Any] = {"timeout": options.get("timeout", 5.0)}
    if name == "sync":
        kw.update(
            group=options.get("group", 1),
            motion=options.get("policy", "dqn"),
            blender=options.get("blender", DEFAULT_BLENDER),
        )
    else:
        kw.update(source_unit=options.get("unit"))
    if name == "l1":
        kw.update(delay=options.get("delay", 0.1))
    return LIVE_DIAGRAMS[name](options["in"], options["out"], **kw)
