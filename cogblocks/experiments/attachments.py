"""What a diagram file keeps beside it: libraries and w̃ tables, networks, L3 policies.

Libraries (``ReachLibrary``) and tables (``SolutionTable``) are ``.npz`` files of their dataclass
fields, read with ``allow_pickle=False``; the encoder and corrector networks are the checkpoints
their loaders read, and the DQN policy its network's state dict, all read with ``weights_only=True``.
The look-ahead policy needs no file: its model is plain data (:func:`lookahead_fields`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["KINDS", "Attachment", "attachment_for", "attachments", "lookahead_fields", "lookahead_policy"]

#: The keys under which a file entry names its type: ``{"data": "ReachLibrary", "file": ...}``.
KINDS = ("data", "network", "policy")


@dataclass(frozen=True)
class Attachment:
    """How one type is written to, and read from, a file beside the diagram."""

    kind: str
    cls: type
    suffix: str
    write: Callable[[Any, Path], None]
    read: Callable[[Path], Any]


def _write_fields(value: Any, path: Path) -> None:
    np.savez(path, **{f.name: np.asarray(getattr(value, f.name)) for f in dataclasses.fields(value) if f.init})


def _reader_of_fields(cls: type) -> Callable[[Path], Any]:
    def read(path: Path) -> Any:
        from cogblocks.sim.reading import open_npz

        with open_npz(path, cls.__name__) as stored:
            return cls(**{k: stored[k].item() if stored[k].ndim == 0 else stored[k] for k in stored.files})

    return read


def _checkpoint_writer(extra: Callable[[Any], dict[str, Any]]) -> Callable[[Any, Path], None]:
    def write(network: Any, path: Path) -> None:
        import torch

        meta = dict(getattr(network, "checkpoint", {}) or {})
        torch.save({**meta, **extra(network), "state_dict": network.state_dict()}, path)

    return write


def _write_policy(policy: Any, path: Path) -> None:
    import torch

    torch.save(policy.network.state_dict(), path)


def attachments() -> dict[str, Attachment]:
    """Every type stored in a file, by the name written in the diagram file."""
    from cogblocks.amplification.corrector import CorrectorNet, load_corrector
    from cogblocks.amplification.encoder import EncoderNet, load_encoder
    from cogblocks.amplification.solution import SolutionTable
    from cogblocks.data.reach import ReachLibrary
    from cogblocks.sync.dqn_policy import DQNPolicy

    def encoder_sizes(net: EncoderNet) -> dict[str, Any]:
        return {"hidden": net.hidden.out_features, "dropout": net.dropout.p}

    return {
        "ReachLibrary": Attachment("data", ReachLibrary, ".npz", _write_fields, _reader_of_fields(ReachLibrary)),
        "SolutionTable": Attachment("data", SolutionTable, ".npz", _write_fields, _reader_of_fields(SolutionTable)),
        "EncoderNet": Attachment("network", EncoderNet, ".pt", _checkpoint_writer(encoder_sizes), load_encoder),
        "CorrectorNet": Attachment("network", CorrectorNet, ".pt", _checkpoint_writer(lambda net: {}), load_corrector),
        "DQNPolicy": Attachment("policy", DQNPolicy, ".pt", _write_policy, DQNPolicy.from_file),
    }


def attachment_for(value: Any) -> tuple[str, Attachment] | None:
    """The name and attachment of ``value``'s exact type, if it is stored in a file."""
    found = attachments().get(type(value).__name__)
    return (type(value).__name__, found) if found is not None and type(value) is found.cls else None


def lookahead_fields(value: Any) -> dict[str, Any] | None:
    """A look-ahead policy as plain fields (its model's, the blender's as a mapping); ``None`` for other values."""
    from cogblocks.sync.lookahead import LookaheadPolicy

    if type(value) is not LookaheadPolicy:
        return None
    model = {f.name: getattr(value.model, f.name) for f in dataclasses.fields(value.model)}
    if model["blender"] is not None:
        model["blender"] = {f.name: getattr(model["blender"], f.name) for f in dataclasses.fields(model["blender"])}
    return {"model": model, "horizon": value.horizon, "every": value.decide_ticks}


def lookahead_policy(fields: dict[str, Any]) -> Any:
    """The look-ahead policy of :func:`lookahead_fields`."""
    from cogblocks.sync.lookahead import LookaheadPolicy
    from cogblocks.sync.model import BlenderParams, SyncModel

    model = dict(fields["model"])
    if model["blender"] is not None:
        model["blender"] = BlenderParams(**model["blender"])
    model = SyncModel(**model)
    return LookaheadPolicy(model, fields["horizon"], fields["every"] * model.dt)
