"""PoP of Amplification: classifier, w̃, online projection, blending and position blocks."""

import warnings
from dataclasses import replace

import numpy as np
import pytest
import torch

from cogblocks.amplification import (
    Buffer,
    EncoderClassifier,
    EncoderNet,
    LibraryProjector,
    SolutionTable,
    VelocityBlender,
    VelocityPositionComputer,
    load_encoder,
    solution_table,
)
from cogblocks.amplification.encoder import (
    FEAR,
    NO_FEAR,
    REST_SPEED,
    UNDECIDED,
    clip_decision,
    movement_length,
    resampling_matrix,
)
from cogblocks.amplification.projector import PrefixProjection
from cogblocks.amplification.solution import library_fingerprint, library_summary, same_library
from cogblocks.blocks import Constant, Playback
from cogblocks.data.features import classifier_inputs, resample_movement
from cogblocks.data.reach import generate_reach_library
from cogblocks.diagrams.amplification_setup import _trained_on, amplification_setup
from cogblocks.sim import Diagram, Simulator
from cogblocks.training.encoder import EncoderConfig, class_report, cross_validate, train_network

torch.set_num_threads(1)  # tiny networks: threads only add contention on a shared machine


@pytest.fixture(scope="module")
def small():
    return generate_reach_library(1, n_subjects=2, n_fear=5, n_no_fear=6)


def tiny_network(seed=0, hidden=8):
    torch.manual_seed(seed)
    net = EncoderNet(hidden=hidden).double()
    with torch.no_grad():
        net.mean.normal_(0.0, 50.0)
        net.scale.uniform_(100.0, 300.0)
    return net.eval()


def test_clipping_rule():
    eps = [0.0, 0.0999, 0.1, 0.5, 0.9, 0.9001, 1.0, np.nan]
    expected = [NO_FEAR, NO_FEAR, UNDECIDED, UNDECIDED, UNDECIDED, FEAR, FEAR, UNDECIDED]
    np.testing.assert_array_equal(clip_decision(eps), expected)
    assert clip_decision(0.95).shape == ()


def test_resampling_matrix_is_resample_movement(small):
    v = small.velocity[0]
    for length in (1, 2, 3, 4, 57, int(small.length[0])):
        got = (resampling_matrix(length) @ v[:length]).T.reshape(-1)
        np.testing.assert_allclose(got, resample_movement(v, length), atol=1e-9)


def test_movement_length():
    v = np.zeros((10, 3))
    assert movement_length(v, 1.0) == 0
    v[2:6, 1] = 5.0
    v[6, 0] = 0.5  # below the rest speed
    assert movement_length(v, 1.0) == 6


def reference_table(net, library, e_des, grid_points=50, threshold=0.9):
    """Algorithm 1 written out: a double loop over the pairs and a loop over c, one blend at a time."""
    grid = np.linspace(0.0, 1.0, grid_points)
    rows = np.flatnonzero(library.fear != bool(e_des))
    cols = np.flatnonzero(library.fear == bool(e_des))
    table = np.empty((len(rows), len(cols)))
    for a, i in enumerate(rows):
        for b, j in enumerate(cols):
            scores = []
            for c in grid:
                blend = c * library.velocity[i] + (1 - c) * library.velocity[j]
                length = movement_length(blend, REST_SPEED)
                eps = float(net.predict(resample_movement(blend, length)))
                scores.append(eps if e_des == 1 else 1.0 - eps)
            scores = np.array(scores)
            ok = scores >= threshold
            if not ok.any():
                ok = scores >= threshold * scores[0]
            table[a, b] = grid[np.flatnonzero(ok).max()]
    return table


@pytest.mark.parametrize("e_des", [1, 0])
def test_solution_table_equals_the_double_loop(small, e_des):
    net = tiny_network()
    # spread the tiny network's outputs so that the threshold and the fallback both occur
    table = solution_table(net, small, e_des, grid_points=12, threshold=0.6, cache_dir=None, chunk=7)
    expected = reference_table(net, small, e_des, grid_points=12, threshold=0.6)
    np.testing.assert_array_equal(table.values, expected)
    assert table.values.shape == ((small.fear != bool(e_des)).sum(), (small.fear == bool(e_des)).sum())
    i, j = table.rows[1], table.cols[2]
    assert table.lookup(i, j) == expected[1, 2]
    with pytest.raises(KeyError):
        table.lookup(j, i)


def test_solution_table_cache(small, tmp_path):
    net = tiny_network()
    first = solution_table(net, small, cache_dir=tmp_path, grid_points=8)
    assert len(list(tmp_path.glob("w_tilde_*.npz"))) == 1
    again = solution_table(net, small, cache_dir=tmp_path, grid_points=8)
    np.testing.assert_array_equal(first.values, again.values)
    with torch.no_grad():
        net.out.bias += 1.0  # other weights: another key, another file
    solution_table(net, small, cache_dir=tmp_path, grid_points=8)
    assert len(list(tmp_path.glob("w_tilde_*.npz"))) == 2


@pytest.mark.parametrize("damage", ["truncated", "garbage", "wrong values"])
def test_corrupt_solution_table_cache_is_reported_and_rebuilt(small, tmp_path, damage):
    net = tiny_network()
    first = solution_table(net, small, cache_dir=tmp_path, grid_points=8)
    (path,) = tmp_path.glob("w_tilde_*.npz")
    content = path.read_bytes()
    if damage == "truncated":  # e.g. a process killed while writing, before writes were atomic
        path.write_bytes(content[: len(content) // 2])
    elif damage == "garbage":
        path.write_bytes(b"not a zip archive" * 10)
    else:
        with np.load(path) as cached:
            key = cached["key"]
        np.savez(path, values=np.full_like(first.values, np.nan), key=key)
    with pytest.warns(UserWarning, match="corrupt w̃ cache file.*rebuilding it") as record:
        again = solution_table(net, small, cache_dir=tmp_path, grid_points=8)
    assert str(path) in str(record[0].message)
    np.testing.assert_array_equal(again.values, first.values)
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # rebuilt in place, no temporary file left
    with np.load(path) as rebuilt:
        np.testing.assert_array_equal(rebuilt["values"], first.values)


def projector_diagram(library, movement, capacity=200, **kwargs):
    d = Diagram()
    v = d.add("v", Playback(movement, unit="mm/s", at_end="zero"))
    p = d.add("p", Playback(np.zeros_like(movement), unit="mm"))
    buf = d.add("buffer", Buffer(capacity))
    proj = d.add("proj", LibraryProjector(library, **kwargs))
    d.connect(v.y, buf.v)
    d.connect(p.y, buf.p)
    d.connect(buf.velocity, proj.velocity)
    d.connect(buf.count, proj.count)
    return d


def naive_projection(library, human, count, metric):
    diff = library.velocity[:, :count] - human[None, :count]
    per_sample = np.linalg.norm(diff, axis=2)
    score = per_sample.mean(axis=1) if metric == "mean" else np.sqrt((per_sample**2).sum(axis=1))
    no_fear, fear = np.flatnonzero(~library.fear), np.flatnonzero(library.fear)
    return no_fear[np.argmin(score[no_fear])], fear[np.argmin(score[fear])]


@pytest.mark.parametrize(
    "metric, dtype, capacity", [("mean", "float64", 200), ("l2", "float64", 40), ("mean", "float32", 25)]
)
def test_incremental_projection_equals_naive_at_every_decision(metric, dtype, capacity):
    library = generate_reach_library(2, n_subjects=3, n_fear=20, n_no_fear=25)
    human = generate_reach_library(5, n_subjects=1, n_fear=0, n_no_fear=1).velocity[0]
    trace = Simulator(
        projector_diagram(library, human, capacity=capacity, metric=metric, dtype=dtype),
        probes={n: f"proj.{n}" for n in ("nearest", "reference", "decisions", "v_r", "horizon")},
    ).run(n_steps=200)
    assert (trace["decisions"][:10] == 0).all() and (trace["nearest"][:10] == -1).all()
    first_reference = None
    for k in range(10, 200, 10):
        assert trace["decisions"][k] == k // 10
        nearest, reference = naive_projection(library, human, k, metric)
        first_reference = reference if first_reference is None else first_reference
        assert trace["nearest"][k] == nearest
        assert trace["reference"][k] == first_reference  # chosen once, after the first window
        assert trace["horizon"][k] == max(library.length[nearest], library.length[first_reference])
    # v_r is the reference's own velocity, sample for sample
    np.testing.assert_array_equal(trace["v_r"][10:], library.velocity[first_reference, 10:])


def test_prefix_projection_past_the_library_length():
    library = np.random.default_rng(0).normal(size=(4, 6, 3))
    human = np.random.default_rng(1).normal(size=(9, 3))
    proj = PrefixProjection(library, metric="l2", dtype="float64", block=4)
    sums = np.zeros(4)
    proj.accumulate(sums, human[:5], 0)
    proj.accumulate(sums, human[5:], 5)
    padded = np.concatenate([library, np.zeros((4, 3, 3))], axis=1)
    expected = ((padded - human) ** 2).sum(axis=(1, 2))
    np.testing.assert_allclose(sums, expected)
    np.testing.assert_allclose(proj.distance(sums, 9), np.sqrt(expected))


def test_projector_candidates_and_validation(small):
    human = small.velocity[0]
    candidates = np.ones(len(small), dtype=bool)
    candidates[0] = False
    trace = Simulator(projector_diagram(small, human, candidates=candidates), probes=["proj.nearest"]).run(n_steps=60)
    assert 0 not in trace["proj.nearest"]
    with pytest.raises(ValueError, match="e_des must be one of"):
        LibraryProjector(small, e_des=2)
    with pytest.raises(ValueError, match="candidates"):
        LibraryProjector(small, candidates=candidates[:-1])


def test_blending_passes_through_then_follows_the_table():
    table = SolutionTable(
        np.array([[0.25, 0.5], [0.75, 1.0]]), np.array([0, 2]), np.array([1, 3]), 1, np.linspace(0, 1, 5)
    )
    library = generate_reach_library(4, n_subjects=1, n_fear=2, n_no_fear=2)
    library.fear[:] = [False, True, False, True]
    human = generate_reach_library(6, n_subjects=1, n_fear=0, n_no_fear=1).velocity[0]
    d = projector_diagram(library, human, interval=10)
    blend = d.add("blend", VelocityBlender(table))
    d.connect("v.y", blend.v_h)
    for port in ("v_r", "nearest", "reference", "decisions"):
        d.connect(f"proj.{port}", f"blend.{port}")
    trace = Simulator(d, probes=["blend.c", "blend.v_a", "proj.v_r", "proj.nearest", "proj.reference"]).run(n_steps=120)
    c = trace["blend.c"]
    assert (c[:10] == 1.0).all()
    np.testing.assert_array_equal(trace["blend.v_a"][:10], human[:10])
    for k in range(10, 120):
        expected = table.lookup(int(trace["proj.nearest"][k]), int(trace["proj.reference"][k]))
        assert c[k] == expected
        if k % 10:
            assert c[k] == c[k - 1]  # c changes only on decision ticks
    v_a = c[:, None] * human[:120] + (1 - c[:, None]) * trace["proj.v_r"]
    np.testing.assert_allclose(trace["blend.v_a"], v_a)


def test_blender_adds_the_correction():
    table = SolutionTable(np.array([[0.5]]), np.array([0]), np.array([1]), 1, np.linspace(0, 1, 3))
    d = Diagram()
    d.add("blend", VelocityBlender(table))
    inputs = {"v_h": [1.0, 2, 3], "v_r": [3.0, 2, 1], "v_u": [0.5, 0, 0]}
    for name, value in inputs.items():
        d.add(name, Constant(value, unit="mm/s"))
        d.connect(f"{name}.y", f"blend.{name}")
    for name, value in (("nearest", 0), ("reference", 1), ("decisions", 3)):
        d.add(name, Constant(np.int64(value)))
        d.connect(f"{name}.y", f"blend.{name}")
    trace = Simulator(d, probes=["blend.v_a"]).run(n_steps=1)
    np.testing.assert_allclose(trace["blend.v_a"][0], [2.5, 2, 2])


def test_position_integration():
    rng = np.random.default_rng(3)
    v, p_h = rng.normal(size=(30, 3)), rng.normal(size=(30, 3))
    v[7] = np.nan  # bad data: the position holds
    d = Diagram()
    d.add("v", Playback(v, unit="mm/s"))
    d.add("p", Playback(p_h, unit="mm"))
    d.add("pos", VelocityPositionComputer())
    d.connect("v.y", "pos.v")
    d.connect("p.y", "pos.p_start")
    p = Simulator(d, probes=["pos.p"]).run(n_steps=30)["pos.p"]
    expected = [p_h[0]]
    for k in range(1, 30):
        expected.append(expected[-1] + (0.01 * v[k] if k != 7 else 0.0))
    np.testing.assert_allclose(p, np.array(expected))


def test_encoder_classifier_restricts_and_resamples(small):
    net = tiny_network(hidden=16)
    movement = small.velocity[3]
    d = Diagram()
    d.add("v", Playback(movement, unit="mm/s", at_end="zero"))
    d.add("p", Playback(np.zeros_like(movement), unit="mm"))
    buf = d.add("buffer", Buffer(200))
    clf = d.add("clf", EncoderClassifier(net))
    d.connect("v.y", buf.v)
    d.connect("p.y", buf.p)
    d.connect(buf.velocity, clf.velocity)
    d.connect(buf.count, clf.count)
    trace = Simulator(d, probes=["clf.eps", "clf.decision", "clf.length"]).run(n_steps=200)
    length = movement_length(movement, REST_SPEED)
    assert trace["clf.length"][-1] == length
    expected = float(net.predict(resample_movement(movement, length)))
    assert trace["clf.eps"][-1] == pytest.approx(expected, abs=1e-12)
    assert trace["clf.decision"][-1] == clip_decision(expected)
    assert np.isnan(clf.classify(np.zeros((5, 3)))[0])  # no movement yet: nothing to classify


def test_tiny_encoder_training_is_deterministic(small):
    inputs = classifier_inputs(small)
    config = EncoderConfig(epochs=3, batch_size=4)
    a = train_network(inputs, small.fear, config, seed=7)
    b = train_network(inputs, small.fear, config, seed=7)
    for (name, x), (_, y) in zip(a.state_dict().items(), b.state_dict().items(), strict=True):
        assert torch.equal(x, y), name
    results = cross_validate(EncoderConfig(epochs=2, batch_size=4, folds=2), seed=1, library=small, log=None)
    assert [r.split_seed for r in results] == [2, 3]
    report = results[0].report
    for name in ("fear", "no_fear"):
        assert report[name]["decided"] + report[name]["undecided"] == pytest.approx(1.0)


def test_class_report_counts():
    report = class_report(np.array([0.95, 0.5, 0.05, 0.02, 0.97]), np.array([True, True, True, False, False]))
    assert report["fear"] == pytest.approx(
        {"n": 3, "decided": 2 / 3, "accuracy": 0.5, "misclassified": 1 / 3, "undecided": 1 / 3}
    )
    assert report["no_fear"]["accuracy"] == 0.5 and report["no_fear"]["misclassified"] == 0.5


def test_shipped_encoder_loads():
    net = load_encoder()
    meta = net.checkpoint
    assert {"split_seed", "library_seed", "val_fraction", "cv"} <= set(meta)
    assert len(meta["cv"]) == 5
    library = generate_reach_library(meta["library_seed"])
    _, val = library.split(meta["val_fraction"], meta["split_seed"])
    eps = net.predict(classifier_inputs(library.subset(val)))
    assert eps.shape == (len(val),) and ((eps >= 0) & (eps <= 1)).all()
    assert np.mean((eps > 0.5) == library.fear[val]) > 0.7


def test_a_library_is_recognised_up_to_rounding_and_not_beyond(small):
    """``same_library`` accepts the library its summary was taken of with every sample moved by a few ulps (another
    CPU's or build's floating point), and refuses a changed label, length or movement; the exact fingerprint does not
    survive the ulps."""
    summary = library_summary(small)
    rng = np.random.default_rng(0)
    ulps = replace(small, velocity=small.velocity * (1.0 + rng.integers(-4, 5, small.velocity.shape) * 2.0**-52))
    assert library_fingerprint(ulps) != library_fingerprint(small)
    assert same_library(summary, small) and same_library(summary, ulps)
    moved = small.velocity.copy()
    moved[3, 10:20] *= 1.001  # a tenth of a percent of one movement's samples
    assert not same_library(summary, replace(small, velocity=moved))
    assert not same_library(summary, replace(small, fear=~small.fear))
    assert not same_library(summary, replace(small, length=small.length + 1))


def test_the_shipped_encoder_is_recognised_on_this_machines_library():
    """Its checkpoint's summary matches the library generated here, so the setup gives no retraining warning; a
    checkpoint with another fingerprint and no summary (an old or foreign one) still gets it."""
    meta = load_encoder().checkpoint
    library = generate_reach_library(meta["library_seed"])
    assert same_library(meta["library_summary"], library)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        amplification_setup.__wrapped__(None, 1)
    assert not _trained_on({"library_sha256": "0" * 64}, library)
    assert _trained_on({"library_sha256": library_fingerprint(library)}, library) and _trained_on({}, library)
