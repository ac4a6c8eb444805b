"""The shield's prediction in progress: doing nothing and following, side by side, as plain data.

:class:`~cogblocks.sync.shielded.ShieldedMotion` advances a :class:`PolicyRollout` a share per tick and keeps it
as declared block state (numbers and arrays), so that a restored snapshot continues it bit for bit.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["PolicyRollout"]


@dataclass
class PolicyRollout:
    """The state of one prediction: doing nothing (row 0) and following the policy (row 1), side by side.

    Plain data, :meth:`ShieldedMotion.advance_rollout` runs it (the wrapped motion computer's predicted state is
    the shield's :attr:`~ShieldedMotion.ahead` copy). A block keeps it as declared state through :meth:`state`
    (numbers and arrays, which a snapshot file holds) and :meth:`from_state`.

    Attributes
    ----------
    theta : ndarray, shape (2, N)
        The participants' predicted own phases of both rows.
    lam : ndarray, shape (2,)
        The blender's predicted λ of both rows.
    model : (ndarray, float)
        Natural frequencies ω (rad/s) and coupling gain K the prediction runs on.
    k : int
        The tick the prediction starts at.
    dt : float
        The tick (s): the policy acts every tick, so the prediction steps by ``dt``.
    steps : int
        Ticks predicted under the policy (row 1) or doing nothing (row 0).
    backup_steps : int
        Steps of ``backup_step`` seconds predicted after them, both rows doing nothing.
    backup_step : float
        The Euler step (s) of the backup part.
    done_steps, done_backup : int
        Ticks and backup steps predicted so far.
    total : ndarray, shape (2,)
        Time integral of the predicted r of both rows so far (r·dt summed); :attr:`scores` divide it by the
        predicted time.
    """

    theta: np.ndarray
    lam: np.ndarray
    model: tuple[np.ndarray, float]
    k: int
    dt: float
    steps: int
    backup_steps: int = 0
    backup_step: float = 0.0
    done_steps: int = 0
    done_backup: int = 0
    total: np.ndarray = field(default_factory=lambda: np.zeros(2))

    @classmethod
    def start(
        cls,
        theta: np.ndarray,
        lam: float,
        model: tuple[np.ndarray, float],
        *,
        k: int,
        dt: float,
        steps: int,
        backup_steps: int = 0,
        backup_step: float = 0.0,
    ) -> PolicyRollout:
        """Both rows at the phases ``theta`` and threshold ``lam`` of tick ``k``."""
        theta = np.tile(np.asarray(theta, dtype=float), (2, 1))
        lam = np.full(2, float(lam))
        return cls(theta, lam, model, k, dt, steps, backup_steps, backup_step)

    def state(self) -> dict[str, Any]:
        """The rollout as numbers and arrays (no copy): its fields, the model split into ``omega`` and ``gain``."""
        fields = {name: value for name, value in vars(self).items() if name != "model"}
        return fields | {"omega": self.model[0], "gain": self.model[1]}

    @classmethod
    def from_state(cls, state: Mapping[str, Any]) -> PolicyRollout:
        """The rollout :meth:`state` returned (its arrays copied)."""
        fields = {name: np.array(value) if isinstance(value, np.ndarray) else value for name, value in state.items()}
        model = (fields.pop("omega"), fields.pop("gain"))
        return cls(model=model, **fields)

    @property
    def following_done(self) -> bool:
        """The part under the policy is predicted (the backup part, if any, may remain)."""
        return self.done_steps >= self.steps

    @property
    def done(self) -> bool:
        return self.following_done and self.done_backup >= self.backup_steps

    @property
    def scores(self) -> np.ndarray:
        """Predicted mean r over the predicted time of (doing nothing, following the policy), once :attr:`done`."""
        if not self.done:
            raise RuntimeError("PolicyRollout: the scores are known only once every step is done")
        return self.total / (self.steps * self.dt + self.backup_steps * self.backup_step)
