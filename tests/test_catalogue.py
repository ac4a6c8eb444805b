"""The catalogue of public blocks lists what users can import, under the names they import it by."""

import importlib
import inspect

import cogblocks.blocks
from cogblocks.catalogue import PACKAGES, package_of, public_blocks
from cogblocks.sim.block import Block


def test_every_block_a_user_can_import_is_listed_once_under_its_import_name():
    listed = public_blocks()
    assert len(set(listed.values())) == len(listed), "a class listed twice"
    for name, cls in listed.items():
        assert cls.__name__ == name
        assert getattr(importlib.import_module(package_of(cls)), name) is cls
    for package in PACKAGES:
        mod = importlib.import_module(package)
        for attr in mod.__all__:
            obj = getattr(mod, attr)
            if inspect.isclass(obj) and issubclass(obj, Block):
                assert listed[attr] is obj, f"{package}.{attr} is public but not in the catalogue"
    assert {"Blender", "VelocityPositionComputer", "PhasePositionComputer", "L2Sync", "OptimalBlender"} <= set(listed)
    assert package_of(listed["Blender"]) == "cogblocks.sync"
    assert package_of(listed["Probe"]) == "cogblocks.blocks"


def test_an_old_import_of_a_moved_block_says_where_it_went():
    import pytest

    with pytest.raises(AttributeError, match=r"KuramotoGroup moved to cogblocks\.sync"):
        cogblocks.blocks.KuramotoGroup  # noqa: B018
    with pytest.raises(AttributeError, match="PhasePositionComputer.*VelocityPositionComputer"):
        cogblocks.blocks.PositionComputer  # noqa: B018
    with pytest.raises(AttributeError, match="no attribute 'Nope'"):
        cogblocks.blocks.Nope  # noqa: B018
