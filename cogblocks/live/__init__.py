"""Live runs on real streams: LSL and OSC blocks, a real-time runner, ready live diagrams.

Needs the ``live`` extra (``pip install -e ".[live]"``: pylsl, python-osc). Names are imported on
first use, so that ``cogblocks.live.config`` (the machine-only LSL configuration) can be set up
before pylsl loads liblsl.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = [
    "LIVE_DIAGRAMS",
    "LSLInlet",
    "LSLOutlet",
    "OSCSender",
    "RealtimeReport",
    "live_l1",
    "live_phase",
    "live_sync",
    "run_realtime",
    "save_report",
]

_HOMES = {
    "LSLInlet": "lsl",
    "LSLOutlet": "lsl",
    "OSCSender": "osc",
    "RealtimeReport": "runner",
    "run_realtime": "runner",
    "save_report": "runner",
    "LIVE_DIAGRAMS": "ready",
    "live_l1": "ready",
    "live_phase": "ready",
    "live_sync": "ready",
}


def __getattr__(name: str) -> Any:
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'cogblocks.live' has no attribute {name!r}")
    return getattr(importlib.import_module(f"cogblocks.live.{home}"), name)


def __dir__() -> list[str]:
    return sorted(__all__)
