"""Playback (cogblocks.blocks.sources): what it plays past the end of its data."""

import numpy as np
import pytest

from cogblocks.blocks import Playback
from cogblocks.sim import SimulationError
from tests.blocks.chain_helpers import run_chain


def test_playback_end_policies():
    data = np.array([1.0, 2.0, 3.0])
    assert run_chain(data, n=5).tolist() == [1, 2, 3, 3, 3]
    assert run_chain(data, n=5, at_end="repeat").tolist() == [1, 2, 3, 1, 2]
    assert run_chain(data, n=5, at_end="zero").tolist() == [1, 2, 3, 0, 0]
    with pytest.raises(SimulationError, match="played all 3 samples"):
        run_chain(data, n=5, at_end="error")
    with pytest.raises(ValueError, match="Playback: data must be an array with at least one row"):
        Playback([])
    with pytest.raises(ValueError, match="Playback: at_end must be one of"):
        Playback(data, at_end="loop")
