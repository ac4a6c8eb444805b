"""The catalogue of public blocks lists what users can import, under the names they import it by."""

import importlib
import inspect

import cogblocks.blocks as package
from cogblocks.blocks.catalogue import PUBLIC_MODULES, public_blocks
from cogblocks.sim import Block


def test_every_block_a_user_can_import_is_listed_once_under_its_import_name():
    listed = public_blocks()
    assert len(set(listed.values())) == len(listed), "a class listed twice"
    for name, cls in listed.items():
        module, _, attr = name.rpartition(".")
        owners = [m for m in PUBLIC_MODULES if m.endswith(f".{module}")]
        where = importlib.import_module(owners[0]) if module else package
        assert getattr(where, attr) is cls, name
    for module in ("cogblocks.blocks", *PUBLIC_MODULES):
        mod = importlib.import_module(module)
        for attr in mod.__all__:
            obj = getattr(mod, attr)
            if inspect.isclass(obj) and issubclass(obj, Block):
                assert obj in listed.values(), f"{module}.{attr} is public but not in the catalogue"
    assert {"Blender", "encoding.PositionComputer", "sync.L2Sync", "optimal_blending.OptimalBlender"} <= set(listed)
