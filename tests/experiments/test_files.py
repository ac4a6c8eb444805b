"""Diagrams as files: a saved and reloaded diagram runs bit for bit like the original; errors name the file."""

import json

import numpy as np
import pytest
import torch

from cogblocks.amplification import RLCorrector, load_corrector, load_encoder, solution_table
from cogblocks.blocks import Constant, Function, Gain, Integrator, Probe
from cogblocks.data.groups import TABLE2
from cogblocks.data.reach import generate_reach_library
from cogblocks.diagrams.amplification import pop_amplification
from cogblocks.diagrams.sync import pop_sync
from cogblocks.experiments.files import diagram_from_dict, diagram_to_dict, load_diagram, save_diagram
from cogblocks.sim import Block, Diagram, DiagramError, Signal, Simulator
from cogblocks.sync import (
    ArmPositions,
    GatedMotion,
    KuramotoGroup,
    MeanPhaseMotion,
    OscillatorMotion,
    RecedingPlanMotion,
)

torch.set_num_threads(1)


def same_run(a, b, n_steps, probes=None):
    ta = Simulator(a, probes=probes).run(n_steps=n_steps)
    tb = Simulator(b, probes=probes).run(n_steps=n_steps)
    assert list(ta) == list(tb) and ta.units == tb.units
    for name in ta:
        np.testing.assert_array_equal(ta[name], tb[name], strict=True)
    return ta


def test_pop_sync_reloads_bit_identical(tmp_path):
    probes = ["group.theta", "l2.lam"]
    # 400 ticks: the default (the planner behind the noise gate) has decided four times and played three of its
    # plans, and the gate has found the group to be the deterministic model
    reference = Simulator(pop_sync(3, blender="deliverable"), probes=probes).run(n_steps=400)
    assert reference["r"].std() > 0  # something happens in the run compared
    for suffix in (".json", ".yaml"):
        loaded = load_diagram(save_diagram(pop_sync(3, blender="deliverable"), tmp_path / f"sync{suffix}"))
        assert type(loaded["l2"]).__name__ == "L2Sync" and isinstance(loaded["l2.motion"], GatedMotion)
        assert isinstance(loaded["l2.motion.model"], RecedingPlanMotion)
        trace = Simulator(loaded, probes=probes).run(n_steps=400)
        assert list(trace) == list(reference) and trace.units == reference.units
        assert len(loaded["l2.motion.model"].plans) == 3 and loaded["l2.motion"].world == "model"
        for name in reference:
            np.testing.assert_array_equal(trace[name], reference[name], strict=True)


def test_the_file_is_plain_data(tmp_path):
    path = save_diagram(pop_sync(3, blender="deliverable"), tmp_path / "sync.json")
    data = json.loads(path.read_text())
    group = data["root"]["diagram"]["blocks"]["group"]
    assert group == {
        "type": "KuramotoGroup",
        "params": {
            "omega": {"tuple": list(TABLE2[3].omega)},
            "gain": TABLE2[3].gain,
            "adjacency": "ring",  # the group's graph, as pop_sync passes it
            "assisted": 5,
        },
    }
    assert ["l2.theta_l2", "group.theta_l2"] in data["root"]["diagram"]["wires"]
    assert not (tmp_path / "sync.data").exists()  # nothing beside it: no data objects


def test_nested_diagrams_periods_and_exposed_ports(tmp_path):
    inner = Diagram(period=0.02)
    gain = inner.add("gain", Gain(np.array([[1.0, 0.5], [0.0, 2.0]]), matrix=True))
    integ = inner.add("integ", Integrator(np.zeros(2), unit="m"), period=0.04)
    inner.connect(gain.y, integ.u)
    inner.expose_input("u", gain.u, spec=Signal(shape=(2,), unit="m"))
    inner.expose_output("x", integ.y)
    outer = Diagram()
    src = outer.add("src", Constant(np.array([1.0, -2.0]), unit="m"))
    outer.add("inner", inner)
    outer.connect(src.y, "inner.u")
    outer.add("x", Probe())
    outer.connect("inner.x", "x.u")
    loaded = diagram_from_dict(diagram_to_dict(outer))
    assert loaded["inner"].period == 0.02 and loaded["inner.integ"].period == 0.04
    trace = same_run(outer, loaded, 41)
    assert trace["x"][-1, 1] != 0


def test_position_domain_with_nested_sensing(tmp_path):
    built = pop_sync(1, domain="position", seed=3, blender="deliverable")
    loaded = load_diagram(save_diagram(built, tmp_path / "sync.json"))
    trace = same_run(
        pop_sync(1, domain="position", seed=3, blender="deliverable"),
        loaded,
        300,
        probes=["sensing.theta_hat", "sensing.p"],
    )
    assert np.ptp(trace["sensing.p"]) > 100  # noisy arm positions, drawn from the seed


def test_pop_amplification_reloads_bit_identical(tmp_path):
    library = generate_reach_library(0, n_subjects=2, n_fear=6, n_no_fear=6)
    encoder = load_encoder()
    table = solution_table(encoder, library, 1)
    human = int(np.flatnonzero(~library.fear)[0])
    movement = (library.velocity[human], library.position[human])

    def build():
        return pop_amplification(
            movement, library, table=table, encoder=encoder, corrector=RLCorrector(load_corrector())
        )

    path = save_diagram(build(), tmp_path / "amp.json")
    files = sorted(p.name for p in (tmp_path / "amp.data").iterdir())
    assert files == ["correctornet2.pt", "encodernet3.pt", "reachlibrary0.npz", "solutiontable1.npz"]
    with np.load(tmp_path / "amp.data" / "reachlibrary0.npz", allow_pickle=False) as stored:
        np.testing.assert_array_equal(stored["velocity"], library.velocity)
    loaded = load_diagram(path)
    assert loaded["l2.projector"].library is loaded["l2"].init_arguments["library"]  # one library, shared
    trace = same_run(build(), loaded, 120, probes=["l2.alpha"])
    assert np.abs(trace["l2.alpha"]).sum() > 0  # the corrector acted: its network was reloaded


def python_error(build):
    with pytest.raises((ValueError, TypeError, DiagramError)) as info:
        build()
    return info.type, str(info.value)


def test_errors_are_those_of_python_and_name_the_file(tmp_path):
    path = save_diagram(pop_sync(1, blender="deliverable"), tmp_path / "sync.json")
    good = json.loads(path.read_text())

    def write(data):
        path.write_text(json.dumps(data))
        return path

    bad = json.loads(json.dumps(good))
    bad["root"]["diagram"]["blocks"]["group"]["params"]["gain"] = -1.0
    kind, message = python_error(lambda: KuramotoGroup(TABLE2[1].omega, -1.0))
    with pytest.raises(kind) as info:
        load_diagram(write(bad))
    assert str(info.value) == f"{path}: block 'group': {message}"

    bad = json.loads(json.dumps(good))
    bad["root"]["diagram"]["blocks"]["group"]["type"] = "KuramotoGrup"
    with pytest.raises(ValueError, match=r"sync\.json: block 'group': unknown block type 'KuramotoGrup'; known: \["):
        load_diagram(write(bad))

    # the default motion computer is the planner behind the noise gate: a bad parameter of either is named
    bad = json.loads(json.dumps(good))
    gated = bad["root"]["diagram"]["blocks"]["l2"]["params"]["motion"]["block"]
    assert gated["type"] == "GatedMotion" and gated["params"]["model"]["block"]["type"] == "RecedingPlanMotion"
    gated["params"]["model"]["block"]["params"]["colour"] = 1
    kind, message = python_error(lambda: RecedingPlanMotion(5, 3, end=1.0, colour=1))
    with pytest.raises(kind) as info:
        load_diagram(write(bad))
    assert str(info.value) == f"{path}: block 'l2': {message}"
    del gated["params"]["model"]["block"]["params"]["colour"]
    gated["params"]["colour"] = 1
    kind, message = python_error(lambda: GatedMotion(RecedingPlanMotion(5, 3, end=1.0), colour=1))
    with pytest.raises(kind) as info:
        load_diagram(write(bad))
    assert str(info.value) == f"{path}: block 'l2': {message}"

    bad = json.loads(json.dumps(good))
    bad["root"]["diagram"]["wires"].append(["order.r", "group.theta_l2"])  # already driven by l2.theta_l2
    kind, message = python_error(lambda: pop_sync(1, blender="deliverable").connect("order.r", "group.theta_l2"))
    with pytest.raises(kind) as info:
        load_diagram(write(bad))
    assert kind is DiagramError and str(info.value) == f"{path}: {message}"

    path.write_text("{not json")
    with pytest.raises(ValueError, match=r"sync\.json: not readable as JSON"):
        load_diagram(path)
    with pytest.raises(ValueError, match="not a cogblocks diagram"):
        diagram_from_dict({"format": "other"})


class HoldPolicy:
    """An L3 policy of the user's: it always holds the frequency."""

    def reset(self, omega_init):
        pass

    def act(self, context):
        return 5


@pytest.mark.parametrize("motion", ["dqn_raw", "lookahead"])
def test_l3_policies_are_stored(tmp_path, motion):
    loaded = load_diagram(save_diagram(pop_sync(1, motion=motion, blender="deliverable"), tmp_path / "sync.json"))
    assert type(loaded["l2.motion"].policy) is type(
        pop_sync(1, motion=motion, blender="deliverable")["l2.motion"].policy
    )
    trace = same_run(pop_sync(1, motion=motion, blender="deliverable"), loaded, 150, probes=["l2.theta_ref"])
    assert np.ptp(trace["l2.theta_ref"]) > 1


class Doubler(Block):
    """A block outside the catalogue."""

    def __init__(self, factor: float = 2.0) -> None:
        super().__init__()
        self.factor = factor
        self.add_input("u")
        self.add_output("y", like="u")

    def output(self, k):
        self.y.value[...] = self.factor * self.u.value


def test_what_cannot_be_saved_is_refused_by_name():
    d = Diagram()
    d.add("f", Function(np.sin, {"u": Signal()}, Signal()))
    with pytest.raises(TypeError, match=r"f: parameter 'fn': a ufunc cannot be stored"):
        diagram_to_dict(d)
    d = Diagram()
    d.add("arms", ArmPositions(3, seed=np.random.default_rng(0)))
    with pytest.raises(TypeError, match=r"arms: parameter 'seed': a Generator cannot be stored"):
        diagram_to_dict(d)
    g = TABLE2[1]
    motion = OscillatorMotion(HoldPolicy(), n=g.n, assisted=g.assisted, gain=g.gain, omega_init=4.0)
    with pytest.raises(TypeError, match=r"l2: parameter 'motion': parameter 'policy': a HoldPolicy cannot"):
        diagram_to_dict(pop_sync(1, motion=motion, blender="deliverable"))
    d = Diagram()
    d.add("double", Doubler(3.0))
    with pytest.raises(TypeError, match=r"double: Doubler is not in the block catalogue"):
        diagram_to_dict(d)
    data = diagram_to_dict(d, blocks={"Doubler": Doubler})
    assert diagram_from_dict(data, blocks={"Doubler": Doubler})["double"].factor == 3.0
    changed = pop_sync(1, blender="deliverable")
    changed.replace("l2.motion", MeanPhaseMotion(5, 3))
    with pytest.raises(TypeError, match=r"l2: L2Sync was changed after construction"):
        diagram_to_dict(changed)
    with pytest.raises(TypeError, match="use save_diagram"):
        movement, library, table = _tiny_amplification()
        diagram_to_dict(pop_amplification(movement, library, table=table))


def _tiny_amplification():
    library = generate_reach_library(0, n_subjects=2, n_fear=6, n_no_fear=6)
    table = solution_table(load_encoder(), library, 1)
    return (library.velocity[0], library.position[0]), library, table
