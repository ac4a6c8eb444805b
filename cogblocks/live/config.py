"""LSL configuration files: one that keeps every stream on this machine, for tests, demos and benchmarks.

liblsl reads the file named by the ``LSLAPICFG`` environment variable the first time it is used;
the variable must therefore be set before the first stream is resolved or created (in practice:
before ``pylsl`` is imported). This module imports nothing from pylsl.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

__all__ = ["MACHINE_ONLY", "machine_only_config", "use_machine_only_config"]

#: An ``lsl_api.cfg`` that discovers and serves streams on the loopback interface only: discovery is
#: machine-scoped, every multicast group is 127.0.0.1, the only known peer is 127.0.0.1, IPv6 is off
#: and the outlets' servers listen on 127.0.0.1, so no LSL packet leaves the machine. liblsl logs
#: warnings and errors only.
MACHINE_ONLY = """\
[ports]
IPv6 = disable

[multicast]
ResolveScope = machine
ListenAddress = 127.0.0.1
MachineAddresses = {127.0.0.1}
LinkAddresses = {127.0.0.1}
SiteAddresses = {127.0.0.1}
OrganizationAddresses = {127.0.0.1}
GlobalAddresses = {127.0.0.1}

[lab]
KnownPeers = {127.0.0.1}
SessionID = {session}

[log]
level = -1
"""


def machine_only_config(directory: str | Path, session: str = "cogblocks") -> Path:
    """Write the machine-only ``lsl_api.cfg`` into ``directory`` and return its path.

    Parameters
    ----------
    directory : str or Path
        Folder to write ``lsl_api.cfg`` into (created if missing).
    session : str
        LSL session id: streams of another session are invisible, which keeps concurrent runs
        (two test processes, say) apart.
    """
    if not session or any(c in session for c in "{}\n=") or session != session.strip():
        raise ValueError(f"machine_only_config: session must be a plain non-empty name, got {session!r}")
    path = Path(directory) / "lsl_api.cfg"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(MACHINE_ONLY.replace("{session}", session))
    return path


def use_machine_only_config(session: str = "cogblocks") -> Path:
    """Point ``LSLAPICFG`` at a fresh machine-only config (in a temporary folder) and return its path.

    Raises
    ------
    RuntimeError
        If pylsl is already imported: liblsl may have read its configuration already.
    """
    if "pylsl" in sys.modules:
        raise RuntimeError("use_machine_only_config() must run before pylsl is imported")
    path = machine_only_config(tempfile.mkdtemp(prefix="cogblocks-lsl-"), session)
    os.environ["LSLAPICFG"] = str(path)
    return path
