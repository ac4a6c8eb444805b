"""Every public block constructor refuses invalid parameters with a ValueError that says what is wrong.

One table, ``CASES``: for every parameter of every public block at least one invalid value, and what
the message must contain: the block's class name, the parameter, the value given and what is allowed
(the form of ``cogblocks.sim.params``: "Block: name must be <allowed>, got <value>"). Parameters that
a composite block documents as passed through to an inner block ("As in Algorithm1Phase", "See
PeriodEstimator") may name that inner block instead.

``test_every_parameter_is_covered`` fails when a public block has a parameter without a case, so a
new block or parameter cannot slip through. Known defects are strict xfails (``reason`` says what
is wrong), so that fixing the block flags the entry for removal.
"""

from __future__ import annotations

import inspect
import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from cogblocks.blocks.specs import PHASE
from cogblocks.catalogue import public_blocks
from cogblocks.sim import Block, Signal


def _blocks() -> dict[str, type]:
    """The public blocks, and the retired ones still built for one release: their constructors are checked too."""
    from cogblocks.sync.guarded import GuardedPacingMotion
    from cogblocks.sync.planned import PlannedMotion

    return {**public_blocks(), "GuardedPacingMotion": GuardedPacingMotion, "PlannedMotion": PlannedMotion}


def block(name: str) -> type:
    return _blocks()[name]


# -- valid arguments the cases start from (built lazily: some need torch or a movement library) -------------


def _tiny_library():
    from cogblocks.data.reach import generate_reach_library

    return generate_reach_library(1, n_subjects=2, n_fear=3, n_no_fear=3)


def _tiny_network():
    from cogblocks.amplification import EncoderNet

    return EncoderNet(hidden=4).double().eval()


def _tiny_table():
    from cogblocks.amplification import SolutionTable

    return SolutionTable(np.ones((2, 2)), np.array([0, 1]), np.array([2, 3]), 1, np.linspace(0, 1, 5))


class _Policy:
    def act(self, context) -> int:
        return 5


def _mean_motion():
    from cogblocks.sync import MeanPhaseMotion

    return MeanPhaseMotion(3, 1)


class _Ports(Block):
    """A model with the motion computers' ports that does not say the group's size."""

    def __init__(self) -> None:
        super().__init__()
        self.add_input("theta", PHASE, feedthrough=False)
        self.add_input("lam", feedthrough=False, default=1.0)
        self.add_output("theta_ref", PHASE)


def _shielded_motion():
    from cogblocks.sync import OscillatorMotion

    return OscillatorMotion(_Policy(), n=3, assisted=0, gain=1.0, omega_init=0.0)


def _discrete_system(dt=0.01):
    import control

    return control.ss([[0.5]], [[1.0]], [[1.0]], [[0.0]], dt)


CURVE = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]

BASES: dict[str, Callable[[], dict[str, Any]]] = {
    "Constant": lambda: {"value": 1.0},
    "Gain": lambda: {"k": 2.0},
    "Saturation": lambda: {"lower": -1.0, "upper": 1.0},
    "LowPass": lambda: {"cutoff": 5.0},
    "RestGate": lambda: {"threshold": 5.0},
    "Function": lambda: {"fn": abs, "inputs": {"u": Signal()}, "outputs": Signal()},
    "Playback": lambda: {"data": [1.0, 2.0]},
    "Mux": lambda: {"n": 2},
    "Demux": lambda: {"n": 2},
    "Select": lambda: {"index": 0},
    "Substitute": lambda: {"index": 0},
    "DiscreteLTI": lambda: {"sys": _discrete_system()},
    "KuramotoGroup": lambda: {"omega": [1.0, 2.0], "gain": 1.0},
    "KuramotoOscillator": lambda: {"omega": 1.0, "gain": 1.0, "n_neighbours": 2},
    "ArmPositions": lambda: {"n": 2},
    "MeanPhaseMotion": lambda: {"n": 3, "assisted": 0},
    "MotionComputer": lambda: {"n": 3, "assisted": 0},
    "OscillatorMotion": lambda: {"policy": _Policy(), "n": 3, "assisted": 0, "gain": 1.0, "omega_init": 0.0},
    "MPCMotion": lambda: {"n": 3, "assisted": 0},
    "GroupIdentifier": lambda: {"n": 3},
    "PacingMotion": lambda: {"n": 3, "assisted": 0},
    "GuardedPacingMotion": lambda: {"n": 3, "assisted": 0},
    "PlannedMotion": lambda: {"n": 3, "assisted": 0, "end": 10.0},
    "RecedingPlanMotion": lambda: {"n": 3, "assisted": 0, "end": 10.0},
    "ShieldedMotion": lambda: {"motion": _shielded_motion()},
    "GatedMotion": lambda: {"model": _mean_motion(), "adjacency": "ring"},
    "ReferenceCustomizer": lambda: {"reference": CURVE},
    "PhaseEstimator3D": lambda: {"reference": CURVE},
    "PhasePositionComputer": lambda: {"reference": CURVE},
    "EncoderClassifier": lambda: {"network": _tiny_network()},
    "LibraryProjector": lambda: {"library": _tiny_library()},
    "VelocityBlender": lambda: {"table": _tiny_table()},
    "L2Sync": lambda: {"motion": _mean_motion(), "assisted": 1},
    "SettledHandover": lambda: {"n": 3, "assisted": 1},
    "L2Amplification": lambda: {"library": _tiny_library(), "table": _tiny_table()},
    "OptimalBlender": lambda: {"library": _tiny_library(), "network": _tiny_network()},
}

# Parameters documented as passed through to an inner block, whose message may name that block.
PASS_THROUGH: dict[str, dict[str, str]] = {
    "PhaseEstimator": dict.fromkeys(
        (
            "unit",
            "centre_periods",
            "accel_window",
            "min_dropout",
            "dropout_period",
            "dropout_steps",
            "holdoff",
            "max_coast",
            "max_period",
        ),
        "Algorithm1Phase",
    ),
    "PhaseEstimator3D": dict.fromkeys(
        ("h", "capacity", "start_speed", "match_ratio", "min_period_fraction"), "PeriodEstimator"
    )
    | dict.fromkeys(
        ("search", "window", "jump_factor", "distance_floor", "velocity_weight", "extrapolate", "amplitude_range"),
        "PhaseComputer",
    )
    | {"customization": "ReferenceCustomizer", "grid": "ReferenceCustomizer"},
    "LibraryProjector": dict.fromkeys(("metric", "dtype"), "PrefixProjection"),
    "L2Amplification": {"candidates": "LibraryProjector"},
    "GatedMotion": dict.fromkeys(
        ("n", "assisted", "adjacency", "fallback", "decide_after", "check_every", "threshold"), "NoiseGate"
    ),
}


@dataclass(frozen=True)
class Case:
    block: str  # key of public_blocks()
    param: str
    value: Any
    allowed: str  # a fragment of the message saying what is allowed
    given: str | None = None  # the fragment showing the value, if not repr(value) (a shape, a type name)
    defect: str | None = None  # known defect: the case is a strict xfail with this reason
    extra: tuple = ()  # (name, value) pairs that replace the block's base arguments for this case


def case(block, param, value, allowed, *, given=None, defect=None, **extra) -> Case:
    return Case(block, param, value, allowed, given, defect, tuple(extra.items()))


CASES = [
    # core
    case("Constant", "value", [1.0, math.nan], "finite"),
    case("Constant", "unit", 5, "string"),
    case("Constant", "wrapped", "yes", "bool"),
    case("Gain", "k", [1.0, math.inf], "finite"),
    case("Gain", "matrix", "yes", "True or False", k=np.eye(2)),
    case("Gain", "unit", 5, "string"),
    case("Sum", "signs", "+*", "'+' and '-'"),
    case("UnitDelay", "initial", math.nan, "finite"),
    case("UnitDelay", "shape", -1, "non-negative"),
    case("UnitDelay", "unit", 5, "string"),
    case("UnitDelay", "wrapped", "yes", "bool"),
    case("UnitDelay", "shape", (2.5,), "non-negative ints"),
    case("Integrator", "initial", math.inf, "finite"),
    case("Integrator", "shape", -1, "non-negative"),
    case("Integrator", "unit", 5, "string"),
    case("Saturation", "lower", math.nan, "finite number"),
    case("Saturation", "upper", -2.0, "[-1.0, inf)"),
    case("LowPass", "cutoff", 0.0, "(0.0, inf)"),
    case("LowPass", "order", 0, "integer >= 1"),
    case("LowPass", "init", "last", "one of ['first', 'zero']"),
    case("LowPass", "gaps", "skip", "one of ['hold', 'repeat']"),
    case("Function", "fn", 5, "callable"),
    case("Function", "inputs", 5, "mapping"),
    case("Function", "outputs", 5, "Signal"),
    case("Function", "feedthrough", "yes", "True or False"),
    case("Playback", "data", [], "at least one row", given="(0,)"),
    case("Playback", "unit", 5, "string"),
    case("Playback", "wrapped", "yes", "bool"),
    case("Playback", "at_end", "loop", "one of ['hold', 'repeat', 'zero', 'error']"),
    case("Playback", "per_run", "yes", "per_run must be True or False"),
    case("Mux", "n", 0, "integer >= 1"),
    case("Demux", "n", 0, "integer >= 1"),
    case("Demux", "unit", 5, "string"),
    case("Demux", "wrapped", "yes", "bool"),
    case("Select", "index", -1, "integer >= 0"),
    case("Substitute", "index", 1.5, "integer >= 0"),
    case("DiscreteLTI", "sys", 5, "StateSpace or TransferFunction", given="int"),
    case("DiscreteLTI", "x0", [1.0, 2.0], "shape (1)", given="(2,)"),
    case("DiscreteLTI", "unit_in", 5, "string"),
    case("DiscreteLTI", "unit_out", 5, "string"),
    # Social Connectedness
    case("KuramotoGroup", "omega", [1.0, math.nan], "finite"),
    case("KuramotoGroup", "gain", -1.0, "[0.0, inf)"),
    case("KuramotoGroup", "adjacency", "full", "'ring', 'all', ('random', p, seed) or an 2x2 matrix"),
    case("KuramotoGroup", "assisted", 5, "[0, 1] or None"),
    case("KuramotoGroup", "theta0", [math.nan], "finite"),
    case("KuramotoGroup", "sparse", "yes", "True, False or None"),
    case("KuramotoGroup", "noise", -0.1, "a number >= 0 or 2 numbers >= 0"),
    case("KuramotoGroup", "noise", [0.1, 0.2, 0.3], "a number >= 0 or 2 numbers >= 0"),
    case("KuramotoGroup", "drift_spread", [0.1, -0.1], "a number >= 0 or 2 numbers >= 0"),
    case("KuramotoGroup", "drift_tau", 0.0, "> 0 s"),
    case("KuramotoGroup", "seed", "x", "None, an int >= 0, a SeedSequence or a Generator"),
    case(
        "KuramotoGroup",
        "theta0",
        [0.0, 0.0, 0.0],
        "shape",
        given="(3,)",
    ),
    case("KuramotoOscillator", "omega", math.nan, "finite number"),
    case("KuramotoOscillator", "gain", -1.0, "[0.0, inf)"),
    case("KuramotoOscillator", "n_neighbours", -1, "integer >= 0"),
    case("KuramotoOscillator", "theta0", math.inf, "finite number"),
    case("ArmPositions", "n", 0, "integer >= 1"),
    case("ArmPositions", "amplitude", -1.0, "> 0"),
    case("ArmPositions", "offset", math.nan, "finite"),
    case("ArmPositions", "noise_std", -1.0, "[0.0, inf)"),
    case("ArmPositions", "seed", "abc", "int"),
    case("Blender", "lam_min", 0.0, "(0.0, inf)"),
    case("Blender", "lam_max", 0.1, "finite number in ["),
    case("Blender", "e_max", -1.0, "(0.0, inf)"),
    case("Blender", "kappa_plus", 0.0, "(0.0, inf)"),
    case("Blender", "kappa_minus", math.nan, "(0.0, inf)"),
    case("Blender", "saturation", "soft", "one of ['hard', 'smooth']"),
    case("Blender", "psi", "gauss", "one of ['triangular', 'bump']"),
    case("Blender", "continuous", 1, "True or False"),
    case("Blender", "slew", 0.0, "(0.0, inf)"),
    case("Blender", "params", 5, "BlenderParams", given="int"),
    case("MeanPhaseMotion", "n", 1, "integer >= 2"),
    case("MeanPhaseMotion", "assisted", 5, "[0, 2]"),
    case("MeanPhaseMotion", "assisted", 1.5, "[0, 2]"),
    case("MotionComputer", "n", 1, "integer >= 2"),
    case("MotionComputer", "assisted", 3, "[0, 2]"),
    case("OscillatorMotion", "policy", 5, "act(context)"),
    case("OscillatorMotion", "n", -1, "integer >= 2"),
    case("OscillatorMotion", "assisted", 7, "[0, 2]"),
    case("OscillatorMotion", "gain", -1.0, "[0.0, inf)"),
    case("OscillatorMotion", "omega_init", 20.0, "[-15.0, 15.0]"),
    case("OscillatorMotion", "adjacency", [[1.0]], "shape (3, 3)", given="(1, 1)"),
    case("MPCMotion", "n", 1, "integer >= 2"),
    case("MPCMotion", "assisted", 5, "[0, 2]"),
    case("MPCMotion", "adjacency", [[1.0]], "shape (3, 3)", given="(1, 1)"),
    case("MPCMotion", "omega", [1.0], "shape (3)", given="(1,)", gain=1.0),
    case("MPCMotion", "gain", -1.0, "[0.0, inf)", omega=[1.0, 2.0, 3.0]),
    case("MPCMotion", "blender", 5, "BlenderParams", given="int"),
    case("MPCMotion", "decide_every", 0.0, "(0.0, inf)"),
    case("MPCMotion", "replan_every", 0, "integer >= 1"),
    case("MPCMotion", "knots", 0, "integer >= 1"),
    case("MPCMotion", "step", 0.0, "(0.0, inf)"),
    case("MPCMotion", "sharpness", 3, "one of"),
    case("MPCMotion", "candidates", 1, "integer >= 2"),
    case("MPCMotion", "iterations_per_tick", 0, "integer >= 1"),
    case("MPCMotion", "trust", 0.0, "(0.0, inf)"),
    case("MPCMotion", "time_limit_ms", 0.0, "(0.0, inf)"),
    case("MPCMotion", "max_iter", 0, "integer >= 1"),
    case("MPCMotion", "forgetting", 0.0, "(0.0, 1.0]"),
    case("MPCMotion", "min_ticks", -1, "integer >= 0"),
    case("PacingMotion", "n", 1, "integer >= 2"),
    case("PacingMotion", "assisted", 5, "[0, 2]"),
    case("PacingMotion", "adjacency", [[1.0]], "shape (3, 3)", given="(1, 1)"),
    case("PacingMotion", "blender", 5, "BlenderParams", given="int"),
    case("PacingMotion", "decide_every", 0.0, "(0.0, inf)"),
    case("PacingMotion", "horizon", 0.0, "(0.0, inf)"),
    case("PacingMotion", "step", -0.1, "(0.0, inf)"),
    case("PacingMotion", "max_steps", 0, "integer >= 1"),
    case("PacingMotion", "frequencies", 1, "integer >= 2"),
    case("PacingMotion", "gates", [4.0], "angles in (0, π]"),
    case("PacingMotion", "margin", -0.1, "[0.0, inf)"),
    case("PacingMotion", "switch_margin", math.nan, "[0.0, inf)"),
    case("PacingMotion", "start", "pace", "one of"),
    case("PacingMotion", "min_ticks", 0, "integer >= 1"),
    case("PacingMotion", "min_excitation", -1.0, "[0.0, inf)"),
    case("GuardedPacingMotion", "n", 1, "integer >= 2"),
    case("GuardedPacingMotion", "assisted", 5, "[0, 2]"),
    case("GuardedPacingMotion", "early", 0.0, "(0.0, inf)"),
    case("GuardedPacingMotion", "tolerance", -0.1, "[0.0, inf)"),
    case("GuardedPacingMotion", "fallback", "pace", "one of"),
    case("GuardedPacingMotion", "first_period", 0, "integer >= 1"),
    case("GuardedPacingMotion", "commit", -1, "integer >= 0"),
    case("GuardedPacingMotion", "end", 0.0, "(0.0, inf)"),
    case("PlannedMotion", "n", 1, "integer >= 2"),
    case("PlannedMotion", "assisted", 5, "[0, 2]"),
    case("PlannedMotion", "end", 0.0, "(0.0, inf)"),
    case("RecedingPlanMotion", "n", 1, "integer >= 2"),
    case("RecedingPlanMotion", "assisted", 5, "[0, 2]"),
    case("RecedingPlanMotion", "end", 0.0, "(0.0, inf)"),
    case("RecedingPlanMotion", "adjacency", [[1.0]], "shape (3, 3)", given="(1, 1)"),
    case("RecedingPlanMotion", "blender", 5, "BlenderParams", given="int"),
    case("RecedingPlanMotion", "decide_every", 0.0, "(0.0, inf)"),
    case("RecedingPlanMotion", "horizon", 0.005, "multiple of 0.01 s"),
    case("RecedingPlanMotion", "compare", -1.0, "(0.0, inf)"),
    case("RecedingPlanMotion", "extend", "mean", "one of"),
    case("RecedingPlanMotion", "sweeps", [(4.0, 4.0)], "(window, tail, knot) triples", given="[(4.0, 4.0)]"),
    case("RecedingPlanMotion", "worker", "process", "one of"),
    case("RecedingPlanMotion", "margin", -1.0, "[0.0, inf)"),
    case("RecedingPlanMotion", "min_ticks", 0, "integer >= 1"),
    case("RecedingPlanMotion", "min_excitation", -1.0, "[0.0, inf)"),
    case("RecedingPlanMotion", "max_iter", 0, "integer >= 1"),
    case("ShieldedMotion", "motion", 5, "MotionComputer block", given="int"),
    case("ShieldedMotion", "adjacency", [[1.0]], "shape (3, 3)", given="(1, 1)"),
    case("ShieldedMotion", "blender", 5, "BlenderParams", given="int"),
    case("ShieldedMotion", "decide_every", -1.0, "(0.0, inf)"),
    case("ShieldedMotion", "horizon", 0.0, "(0.0, inf)"),
    case("ShieldedMotion", "margin", -0.1, "[0.0, inf)"),
    case("ShieldedMotion", "backup", -1.0, "[0.0, inf)"),
    case("ShieldedMotion", "switch_margin", math.nan, "[0.0, inf)"),
    case("ShieldedMotion", "min_ticks", 0, "integer >= 1"),
    case("ShieldedMotion", "min_excitation", -1.0, "[0.0, inf)"),
    case("GroupIdentifier", "n", 1, "integer >= 2"),
    case("GroupIdentifier", "adjacency", [[1.0]], "shape (3, 3)", given="(1, 1)"),
    case("GroupIdentifier", "assisted", 5, "[0, 2]"),
    case("GroupIdentifier", "forgetting", 1.5, "(0.0, 1.0]"),
    case("GroupIdentifier", "prior_omega", math.nan, "finite number"),
    case("GroupIdentifier", "prior_gain", math.inf, "finite number"),
    case("GroupIdentifier", "max_rate", 0.0, "(0.0, inf)"),
    # sensor streams and L1
    case("KalmanEstimator", "model", "cj", "one of ['cv', 'ca']"),
    case("KalmanEstimator", "process_noise", 0.0, "(0.0, inf)"),
    case("KalmanEstimator", "measurement_noise", -1.0, "(0.0, inf)"),
    case("KalmanEstimator", "dims", 0, "integer >= 1"),
    case("KalmanEstimator", "unit", "", "non-empty string"),
    case("KalmanEstimator", "gate", 1.0, "(0.0, 1.0)"),
    case("KalmanEstimator", "max_rejections", 0, "integer >= 1"),
    case("KalmanEstimator", "freeze_frames", 0, "integer >= 1"),
    case("RestGate", "threshold", -1.0, "[0.0, inf)"),
    case("RestGate", "threshold", math.nan, "finite number"),
    case("RestGate", "unit", "", "non-empty string"),
    case("L1", "delay", -0.1, "[0.0, inf)"),
    case(
        "L1",
        "smoothing",
        "yes",
        "True or False",
    ),
    case("L1", "estimator", 5, "KalmanEstimator", given="int"),
    case("KinematicPredictor", "horizon", -1.0, "[0.0, inf)"),
    case("KinematicPredictor", "smoothing", "yes", "True or False"),
    case("KinematicPredictor", "unit", 5, "string"),
    # 1D phase
    case("Algorithm1Phase", "unit", "", "non-empty string"),
    case("Algorithm1Phase", "centre_periods", 0, "integer >= 1"),
    case("Algorithm1Phase", "accel_window", -1.0, "[0.0, inf)"),
    case("Algorithm1Phase", "min_dropout", -1.0, "[0.0, inf)"),
    case("Algorithm1Phase", "holdoff", math.nan, "[0.0, inf)"),
    case("Algorithm1Phase", "max_period", 0.0, "(0.0, inf)"),
    case("Algorithm1Phase", "cutoff", -3.0, "(0.0, inf)"),
    case("Algorithm1Phase", "order", 0, "integer >= 1"),
    case("PhaseEstimator", "cutoff", 0.0, "(0.0, inf)"),
    case("PhaseEstimator", "order", 0, "integer >= 1"),
    case("PhaseEstimator", "unit", "", "non-empty string"),
    case("PhaseEstimator", "centre_periods", 0, "integer >= 1"),
    case("PhaseEstimator", "accel_window", -1.0, "[0.0, inf)"),
    case("PhaseEstimator", "min_dropout", -1.0, "[0.0, inf)"),
    case("PhaseEstimator", "holdoff", -1.0, "[0.0, inf)"),
    case("PhaseEstimator", "max_period", 0.0, "(0.0, inf)"),
    case("PhaseEstimator", "compensate", "yes", "True or False"),
    case("PhaseEstimator", "front_end", "median", "one of ['lowpass', 'kalman']"),
    case("Algorithm1Phase", "derivative_inputs", "yes", "True or False"),
    case("Algorithm1Phase", "remove_transient", "yes", "True or False"),
    case("Algorithm1Phase", "dropout_period", 0.0, "(0.0, inf)"),
    case("Algorithm1Phase", "dropout_steps", -1.0, "(0.0, inf)"),
    case("Algorithm1Phase", "max_coast", math.nan, "(0.0, inf)"),
    case("PhaseEstimator", "spike_factor", 0.0, "(0.0, inf)"),
    case("ReferenceCustomizer", "customization", "rigid", "one of ['affine', 'deliverable']"),
    case("ReferenceCustomizer", "grid", 4, "integer >= 8"),
    case("PhaseEstimator3D", "grid", 4, "integer >= 8"),
    case("PhaseEstimator3D", "velocity", "spline", "one of ['difference', 'kalman']"),
    case("PhaseEstimator3D", "kalman_model", "cj", "one of ['cv', 'ca']"),
    # 3D phase
    case("PeriodEstimator", "h", 10, "(0.0, 1.0]"),
    case("PeriodEstimator", "capacity", 5, "integer >= 10"),
    case("PeriodEstimator", "start_speed", -1.0, "[0.0, inf)"),
    case("PeriodEstimator", "match_ratio", 0.0, "(0.0, 1.0]"),
    case("PeriodEstimator", "min_period_fraction", 1.0, "[0.0, 1.0)"),
    case("ReferenceCustomizer", "reference", [[0.0, 0.0]], "shape (any, 3)", given="(1, 2)"),
    case("PhaseComputer", "search", "fast", "one of ['warm', 'full']"),
    case("PhaseComputer", "window", 0, "(0.0, 1.0]"),
    case("PhaseComputer", "extrapolate", -1.0, "[0.0, inf)"),
    case("PhaseComputer", "amplitude_range", 0.5, "[1.0, inf)"),
    case("PhaseComputer", "jump_factor", 1.0, "(1.0, inf)"),
    case("PhaseComputer", "distance_floor", -1.0, "[0.0, inf)"),
    case("PhaseComputer", "velocity_weight", -0.01, "[0.0, inf)"),
    case(
        "PhaseEstimator3D",
        "reference",
        [[0.0, 0.0]],
        "shape (any, 3)",
        given="(1, 2)",
    ),
    case("PhaseEstimator3D", "h", 10, "(0.0, 1.0]"),
    case("PhaseEstimator3D", "capacity", 5, "integer >= 10"),
    case("PhaseEstimator3D", "start_speed", -1.0, "[0.0, inf)"),
    case("PhaseEstimator3D", "match_ratio", 2.0, "(0.0, 1.0]"),
    case("PhaseEstimator3D", "min_period_fraction", -0.5, "[0.0, 1.0)"),
    case("PhaseEstimator3D", "search", "fast", "one of ['warm', 'full']"),
    case("PhaseEstimator3D", "window", 0, "(0.0, 1.0]"),
    case("PhaseEstimator3D", "jump_factor", 0.5, "(1.0, inf)"),
    case("PhaseEstimator3D", "distance_floor", -1.0, "[0.0, inf)"),
    case("PhaseEstimator3D", "velocity_weight", -1.0, "[0.0, inf)"),
    case("PhasePositionComputer", "reference", [[0.0, 0.0]], "shape (any, 3)", given="(1, 2)"),
    case("PhasePositionComputer", "noise_std", -1.0, "[0.0, inf)"),
    case("PhasePositionComputer", "seed", "abc", "int"),
    # PoP of Amplification
    case("Buffer", "capacity", 0, "integer >= 1"),
    case("EncoderClassifier", "network", 5, "EncoderNet", given="int"),
    case("EncoderClassifier", "rest_speed", -1.0, "[0.0, inf)"),
    case("LibraryProjector", "library", 5, "ReachLibrary", given="int"),
    case("LibraryProjector", "e_des", 2, "one of [0, 1]"),
    case("LibraryProjector", "interval", 0, "integer >= 1"),
    case("LibraryProjector", "metric", "max", "one of ['mean', 'l2']"),
    case("LibraryProjector", "dtype", "int8", "one of ['float32', 'float64']"),
    case("LibraryProjector", "candidates", [True], "shape (6,)", given="(1,)"),
    case("VelocityBlender", "table", 5, "SolutionTable", given="int"),
    case("RLCorrector", "network", 5, "CorrectorNet", given="int"),
    case("RLCorrector", "gain", 0.0, "(0.0, inf)"),
    case("RLCorrector", "interval", 0, "integer >= 1"),
    # the L2 architectures as blocks
    case("GatedMotion", "model", 5, "inputs ['theta', 'lam'] and outputs ['theta_ref']", given="int"),
    case("GatedMotion", "n", 4, "the model's n = 3"),
    case("GatedMotion", "n", 1, "integer >= 2", model=_Ports(), assisted=0),
    case("GatedMotion", "assisted", 2, "the model's assisted = 1"),
    case("GatedMotion", "assisted", 3, "[0, 2]", model=_Ports(), n=3),
    case("GatedMotion", "adjacency", [[1.0]], "shape (3, 3)", given="(1, 1)"),
    case("GatedMotion", "fallback", "median", "one of ['mean', 'nothing']"),
    case("GatedMotion", "decide_after", 0.0, "(0.0, inf)"),
    case("GatedMotion", "check_every", -1.0, "(0.0, inf)"),
    case("GatedMotion", "threshold", math.nan, "[0.0, inf)"),
    case("L2Sync", "motion", 5, "inputs ['theta', 'lam'] and outputs ['theta_ref']", given="int"),
    case("L2Sync", "assisted", -1, "integer >= 0"),
    case("SettledHandover", "n", 0, "integer >= 1"),
    case("SettledHandover", "assisted", 3, "[0, 2]"),
    case("SettledHandover", "assisted", True, "[0, 2]"),
    case("SettledHandover", "slew", 0.0, "(0.0, inf)"),
    case("L2Sync", "assisted", 0, "assisted index 1"),
    case("L2Sync", "blender", 5, "outputs ['theta_l2', 'lam']", given="int"),
    case("L2Amplification", "library", 5, "ReachLibrary", given="int"),
    case("L2Amplification", "step_limit", -1.0, "(0.0, inf)"),
    case("L2Amplification", "table", 5, "SolutionTable for e_des=1", given="int"),
    case("L2Amplification", "corrector", 5, "outputs ['v_u', 'alpha']", given="int"),
    case("L2Amplification", "blending", 5, "outputs ['v_a', 'c']", given="int"),
    case("L2Amplification", "e_des", 2, "one of [0, 1]"),
    case("L2Amplification", "interval", 300, "[1, capacity=200]"),
    case("L2Amplification", "capacity", 0, "integer >= 1"),
    case("L2Amplification", "candidates", [True], "shape (6,)", given="(1,)"),
    # optimisation-based blending
    case("OptimalBlender", "library", 5, "ReachLibrary", given="int"),
    case("OptimalBlender", "network", 5, "EncoderNet", given="int"),
    case("OptimalBlender", "table", 5, "SolutionTable for e_des=1", given="int"),
    case("OptimalBlender", "e_des", -1, "one of [0, 1]"),
    case("OptimalBlender", "margin", 0.5, "[0.0, 0.09"),
    case("OptimalBlender", "delta_pos", 0.0, "(0.0, inf)"),
    case("OptimalBlender", "terminal_margin", 25.0, "[0.0, 20.0)"),
    case("OptimalBlender", "end_speed", -1.0, "[0.0, inf)"),
    case("OptimalBlender", "knot_spacing", 0, "integer >= 1"),
    case("OptimalBlender", "time_limit_ms", 0.0, "(0.0, inf)"),
    case("OptimalBlender", "solver", "bonmin", "one of ['sqpmethod', 'ipopt', 'linearised']"),
    case("OptimalBlender", "subspace", 5, "subspace must be a MovementSubspace", given="int"),
    case("OptimalBlender", "realism", -1.0, "[0.0, inf)"),
    case("OptimalBlender", "sharpness", math.inf, "(0.0, inf)"),
    case("OptimalBlender", "rest_speed", -1.0, "[0.0, inf)"),
    case("OptimalBlender", "solve_ticks", 0, "integer >= 1"),
    case("OptimalBlender", "iterations", 0, "integer >= 1"),
    case("OptimalBlender", "emit", "predicted", "one of ['human', 'plan', 'tail']"),
    case("OptimalBlender", "track_past", 1, "True or False"),
    case("OptimalBlender", "removal_margin", 0.5, "[0.0, 0.09"),
    case("OptimalBlender", "guard_rest", 1, "True or False"),
    case("OptimalBlender", "guard_margin", 20.0, "[0.0, 20.0)"),
    case("OptimalBlender", "gradient", "dense", "one of ['stacked', 'blocks']"),
    case("OptimalBlender", "predict_setup", 1, "True or False"),
    case("OptimalBlender", "neighbours", 0, "integer >= 1"),
]


def required_parameters(cls: type) -> set[str]:
    """The constructor's parameters that need a case: all but ``period`` and ``*args``/``**kwargs``."""
    params = inspect.signature(cls.__init__).parameters.values()
    kinds = (inspect.Parameter.VAR_POSITIONAL, inspect.Parameter.VAR_KEYWORD)
    return {p.name for p in params if p.name not in ("self", "period") and p.kind not in kinds}


def test_every_parameter_is_covered():
    covered = {(c.block, c.param) for c in CASES}
    missing = [
        f"{name}.{param}"
        for name, cls in sorted(public_blocks().items())
        for param in sorted(required_parameters(cls) - set(PASS_THROUGH.get(name, {})))
        if (name, param) not in covered
    ]
    assert not missing, f"constructor parameters without an invalid-value case in CASES: {missing}"


def test_cases_name_real_parameters():
    blocks = _blocks()
    wrong = [
        f"{c.block}.{c.param}"
        for c in CASES
        if c.block in blocks and c.param not in required_parameters(blocks[c.block])
    ]
    assert not wrong, f"CASES name parameters the blocks do not have: {wrong}"


def _params():
    blocks = _blocks()
    for c in CASES:
        marks = [pytest.mark.xfail(strict=True, reason=c.defect)] if c.defect else []
        if c.block not in blocks:  # a module being written
            marks = [pytest.mark.skip(reason=f"{c.block} is not public (yet)")]
        yield pytest.param(c, id=f"{c.block}.{c.param}={c.value!r}"[:80], marks=marks)


@pytest.mark.parametrize("c", list(_params()))
def test_invalid_parameter_is_refused_with_a_clear_message(c: Case):
    cls = block(c.block)
    kwargs = BASES.get(c.block, dict)() | dict(c.extra)
    kwargs[c.param] = c.value
    with pytest.raises(ValueError) as info:
        cls(**kwargs)
    message = str(info.value)
    owners = {cls.__name__, PASS_THROUGH.get(c.block, {}).get(c.param, cls.__name__)}
    assert any(re.match(rf"{owner}\b", message) for owner in owners), f"names no block of {owners}: {message}"
    assert re.search(rf"\b{c.param}\b", message), f"does not name the parameter {c.param!r}: {message}"
    given = repr(c.value) if c.given is None else c.given
    assert given in message, f"does not show the value given ({given}): {message}"
    assert c.allowed in message, f"does not say what is allowed ({c.allowed}): {message}"
