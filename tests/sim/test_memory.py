"""Runs too big for the machine are refused before they allocate, naming what is too big and the way out."""

import numpy as np
import pytest

from cogblocks.blocks import Playback
from cogblocks.sim import Diagram, Simulator
from cogblocks.sim.memory import MEMORY_LIMIT_ENV, memory_limit
from cogblocks.sync.group import KuramotoGroup


def test_an_all_to_all_group_too_big_is_refused_naming_the_block_the_size_and_a_sparse_graph(monkeypatch):
    monkeypatch.setenv(MEMORY_LIMIT_ENV, "8G")
    with pytest.raises(ValueError) as caught:
        KuramotoGroup(np.ones(60_000), 0.1, adjacency="all")
    message = str(caught.value)
    assert message.startswith("KuramotoGroup:") and "60000" in message
    assert "GiB" in message and "8.0 GiB allowed" in message
    assert "sparse" in message and "ring" in message


def test_the_default_limit_is_a_share_of_the_machine(monkeypatch):
    import psutil

    monkeypatch.delenv(MEMORY_LIMIT_ENV, raising=False)
    limit = memory_limit()
    assert 0 < limit <= psutil.virtual_memory().total
    monkeypatch.setenv(MEMORY_LIMIT_ENV, "0")
    assert memory_limit() is None  # switched off
    monkeypatch.setenv(MEMORY_LIMIT_ENV, "lots")
    with pytest.raises(ValueError, match=MEMORY_LIMIT_ENV):
        memory_limit()


def _wide(n):
    d = Diagram()
    d.add("src", Playback(np.zeros((3, n))))
    return d


def test_a_probe_too_big_is_refused_before_the_run_naming_the_probe_and_decimate(monkeypatch):
    monkeypatch.setenv(MEMORY_LIMIT_ENV, "1M")
    sim = Simulator(_wide(1000), probes=["src.y"])
    with pytest.raises(ValueError) as caught:
        sim.run(n_steps=1000)  # 1000 x 1000 float64: 7.6 MiB
    message = str(caught.value)
    assert "'src.y'" in message and "7.6 MiB" in message and "decimate=" in message
    assert sim.compiled.k == 0  # refused before any tick ran
    trace = Simulator(_wide(1000), probes=["src.y"], decimate=10).run(n_steps=1000)
    assert trace["src.y"].shape == (100, 1000)


def test_a_probe_on_1e5_phases_over_20000_ticks_is_refused(monkeypatch):
    monkeypatch.setenv(MEMORY_LIMIT_ENV, "8G")
    d = Diagram()
    d.add("group", KuramotoGroup(np.ones(100_000), 0.1))  # a ring: cheap to build
    with pytest.raises(ValueError, match=r"probe 'group.theta'.*14.9 GiB.*decimate="):
        Simulator(d, probes=["group.theta"]).run(n_steps=20_000)
