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
    "OSCReceiver",
    "OSCSender",
    "load_session",
    "replay_session",
    "write_session",
    "RealtimeReport",
    "live_l1",
    "live_phase",
    "live_sync",
    "run_realtime",
    "save_report",
]

_LAZY = {
    "LSLInlet": "cogblocks.live.inlet",
    "LSLOutlet": "cogblocks.live.outlet",
    "OSCReceiver": "cogblocks.live.osc_in",
    "OSCSender": "cogblocks.live.osc",
    "load_session": "cogblocks.live.replay",
    "replay_session": "cogblocks.live.replay",
    "write_session": "cogblocks.live.session",
    "RealtimeReport": "cogblocks.live.runner",
    "run_realtime": "cogblocks.live.runner",
    "save_report": "cogblocks.live.runner",
    "LIVE_DIAGRAMS": "cogblocks.live.ready",
    "live_l1": "cogblocks.live.ready",
    "live_phase": "cogblocks.live.ready",
    "live_sync": "cogblocks.live.ready",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'cogblocks.live' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
