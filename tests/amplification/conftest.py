"""Fixtures shared by ``test_optimal_tail.py`` and ``test_past.py``. A module defining its own ``setup`` or
``networks`` (as ``test_subspace.py`` does) uses its own: pytest's override."""

import pytest

from cogblocks.diagrams.amplification import amplification_setup
from cogblocks.diagrams.amplification_setup import blender_networks


@pytest.fixture(scope="module", params=[1, 0])
def setup(request):
    """The amplification set-up encoding fear (1), then removing it (0)."""
    return amplification_setup(None, request.param)


@pytest.fixture(scope="module")
def networks(setup):
    """The shipped blender networks on ``setup``'s encoder."""
    return blender_networks(setup.encoder)
