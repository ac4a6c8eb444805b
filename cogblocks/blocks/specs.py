"""Signal specs shared by the architectures: phases, 3D positions and velocities, counters and flags."""

from __future__ import annotations

from typing import Any

import numpy as np

from cogblocks.sim import Signal

__all__ = ["COUNT", "FLAG", "PHASE", "POSITION", "VELOCITY", "open_spec"]


def open_spec(shape: Any, unit: str | None, wrapped: bool | None) -> Signal:
    return Signal(shape=shape, dtype=None, unit=unit, wrapped=wrapped)


POSITION = Signal(shape=(3,), unit="mm")
VELOCITY = Signal(shape=(3,), unit="mm/s")
PHASE = Signal(unit="rad", wrapped=True)
COUNT = Signal(dtype=np.int64, unit="1")
FLAG = Signal(dtype=np.bool_, unit="1")
