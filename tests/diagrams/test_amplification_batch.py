"""The PoP of Amplification on a batch: playback, buffers and encoder run the batch at once, the rest per run."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from cogblocks.blocks import Playback
from cogblocks.diagrams.amplification import pop_amplification
from cogblocks.diagrams.amplification_setup import amplification_setup
from cogblocks.sim import DiagramError, Simulator
from cogblocks.sim.batch import PerRowWarning

torch.set_num_threads(1)  # tiny networks: threads only add contention on a shared machine


@pytest.fixture(scope="module")
def setup():
    return amplification_setup()


def test_each_run_of_a_batch_replays_its_own_movement(setup):
    lib = setup.movements
    movements = [(lib.velocity[i], lib.position[i]) for i in (0, 3)]
    n = len(movements[0][0]) + 20

    def diagram(movement):
        return pop_amplification(movement, lib, table=setup.table, encoder=setup.encoder)

    alone = [Simulator(diagram(m)).run(n_steps=n) for m in movements]
    d = diagram(movements[0])
    d.replace("human_v", Playback(np.stack([m[0] for m in movements], 1), unit="mm/s", at_end="zero", per_run=True))
    d.replace("human_p", Playback(np.stack([m[1] for m in movements], 1), unit="mm", at_end="hold", per_run=True))
    with pytest.warns(PerRowWarning, match="l2.projector"):
        sim = Simulator(d, batch=2)
    assert {"human_v", "human_p", "altered", "encoder", "l2.buffer"}.isdisjoint(sim.compiled.per_row)
    trace = sim.run(n_steps=n)
    for b, one in enumerate(alone):
        run = trace.run(b)
        for name in ("v_h", "p_h", "v_a", "p_a", "v_r", "c"):
            assert np.array_equal(run[name], one[name]), name
        # the network's product over the batch rounds differently from one run's
        np.testing.assert_allclose(run["eps"], one["eps"], rtol=0, atol=1e-12)


def test_per_run_recordings_need_their_batch():
    play = Playback(np.zeros((5, 3, 2)), per_run=True)
    play.batch = 2
    with pytest.raises(DiagramError, match="data holds 3 runs"):
        play.setup()
