"""Training environment of the RL corrector of the PoP of Amplification, vectorised over episodes.

The corrector does not change what the projector sees (the buffer holds the human movement), so
the blend ``c(t)·v_h(t) + (1 − c(t))·v_r(t)`` and the projector's horizon of a movement are the same
whatever the corrector does. :func:`record_episodes` records them once per movement by running the
:class:`~cogblocks.amplification.L2Amplification` diagram itself (without correction), so the
environment cannot drift from the architecture. :class:`AmplificationEnv` then replays the
corrector's loop in NumPy for a batch of episodes, exactly as
:class:`~cogblocks.amplification.RLCorrector` and :class:`~cogblocks.amplification.VelocityPositionComputer`
run it in the diagram::

    v_u(t) = k_u α(t) ⊙ (p_h(t−1) − p_a(t−1)),  v_a(t) = blend(t) + v_u(t),  p_a(t) = p_a(t−1) + dt v_a(t)

One environment step is one decision of the corrector: an action held for ``interval`` ticks, the
discounted sum of the per-tick rewards (16)–(17) and the state at the last tick.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cogblocks.amplification import SolutionTable
from cogblocks.amplification.corrector import ACTIONS, corrector_state, reward_constants, step_reward
from cogblocks.blocks import Playback
from cogblocks.data.reach import ReachLibrary
from cogblocks.sim import Diagram, Simulator
from cogblocks.sim.timing import BASE_STEP

__all__ = ["AmplificationEnv", "Episodes", "record_episodes"]


@dataclass
class Episodes:
    """What the corrector's loop needs of each movement, padded to ``T`` ticks.

    Attributes
    ----------
    v_h, p_h : numpy.ndarray, shape (B, T, 3)
        Human velocity (zero after the end) and position (held).
    blend : numpy.ndarray, shape (B, T, 3)
        The altered velocity without correction.
    horizon : numpy.ndarray of int, shape (B, T)
        The projector's horizon output at each tick.
    settle : numpy.ndarray of int, shape (B,)
        Settling horizon ``k_s`` of the reward: ``max(length(v_h), length(v_r))``.
    """

    v_h: np.ndarray
    p_h: np.ndarray
    blend: np.ndarray
    horizon: np.ndarray
    settle: np.ndarray

    def __len__(self) -> int:
        return len(self.v_h)


def record_episodes(
    movements: ReachLibrary,
    table: SolutionTable,
    humans: np.ndarray,
    *,
    leave_one_out: bool = True,
    interval: int = 10,
) -> Episodes:
    """Run the architecture without correction on each human movement of the library and record it.

    Parameters
    ----------
    movements : ReachLibrary
        The library the projector searches; the humans are taken from it.
    table : SolutionTable
        w̃ on ``movements``.
    humans : array_like of int
        Indices (in ``movements``) of the movements to replay.
    leave_one_out : bool
        Keep the replayed movement out of the projector's candidates, so that, as in validation,
        the human is not in the library.
    interval : int
        ΔT of the projector.
    """
    from cogblocks.amplification import L2Amplification

    n_steps = movements.max_len
    columns: dict[str, list[np.ndarray]] = {"v_h": [], "p_h": [], "blend": [], "horizon": []}
    settle = []
    for human in np.asarray(humans, dtype=np.int64):
        candidates = np.ones(len(movements), dtype=bool)
        candidates[human] = not leave_one_out
        d = Diagram()
        v = d.add("v", Playback(movements.velocity[human], unit="mm/s", at_end="zero"))
        p = d.add("p", Playback(movements.position[human], unit="mm", at_end="hold"))
        l2 = d.add(
            "l2",
            L2Amplification(
                movements, table, e_des=table.e_des, interval=interval, capacity=n_steps, candidates=candidates
            ),
        )
        d.connect(v.y, l2.v_h)
        d.connect(p.y, l2.p_h)
        probes = {
            "v_h": "v.y",
            "p_h": "p.y",
            "blend": "l2.v_a",
            "horizon": "l2.projector.horizon",
            "reference": "l2.reference",
        }
        trace = Simulator(d, probes=probes).run(n_steps=n_steps)
        for name in columns:
            columns[name].append(trace[name])
        settle.append(max(movements.length[human], movements.length[int(trace["reference"][-1])]))
    arrays = {name: np.stack(values) for name, values in columns.items()}
    return Episodes(settle=np.array(settle, dtype=np.int64), **arrays)


class AmplificationEnv:
    """The corrector's closed loop for a batch of episodes (see the module docstring).

    Parameters
    ----------
    episodes : Episodes
        Recorded movements.
    gain : float
        ``k_u`` in 1/s.
    interval : int
        Ticks between two decisions; the first decision acts from tick ``interval`` on.
    dt : float
        Tick in seconds.
    gamma : float
        Discount per tick.
    """

    def __init__(
        self, episodes: Episodes, *, gain: float = 6.0, interval: int = 10, dt: float = BASE_STEP, gamma: float = 0.99
    ) -> None:
        self.episodes = episodes
        self.gain, self.interval, self.dt, self.gamma = gain, interval, dt, gamma
        self.n_steps = episodes.v_h.shape[1]
        self._discount = gamma ** np.arange(interval)
        self.rows = np.zeros(0, dtype=np.int64)

    @property
    def batch_size(self) -> int:
        """Episodes running."""
        return len(self.rows)

    def reset(self, rows: np.ndarray) -> np.ndarray:
        """Start episodes of the given movements; run the first ``interval`` ticks (α = 0).

        Returns
        -------
        numpy.ndarray, shape (B, 13)
            The state at tick ``interval − 1``, from which the first action is chosen.
        """
        self.rows = np.asarray(rows, dtype=np.int64)
        r_in, r_exit = reward_constants(self.episodes.settle[self.rows].astype(np.float64), gamma=self.gamma)
        self._r_in, self._r_exit = r_in, r_exit
        b = len(self.rows)
        self.t = 0
        self.p_a = self.episodes.p_h[self.rows, 0].copy()
        self.v_a = self.episodes.blend[self.rows, 0].copy()
        self.gap = np.zeros((b, 3))  # p_h − p_a of the previous tick, as the block stores it
        self.inside = np.zeros(b, dtype=bool)
        self.done = np.zeros(b, dtype=bool)
        self.discounted_return = np.zeros(b)
        self._advance(np.zeros((b, 3)), self.interval - 1)
        self.discounted_return[:] = 0.0  # returns count from the first decision, as in the prototype
        return self.state()

    def state(self) -> np.ndarray:
        """The corrector's state at the current tick, shape (B, 13)."""
        e, rows, t = self.episodes, self.rows, self.t
        return corrector_state(e.p_h[rows, t], self.p_a, e.v_h[rows, t], self.v_a, e.horizon[rows, t])

    def _advance(self, alpha: np.ndarray, ticks: int) -> np.ndarray:
        """Run ``ticks`` ticks with the action ``alpha`` (B, 3); the discounted reward of each episode."""
        e, rows = self.episodes, self.rows
        total = np.zeros(len(rows))
        for j in range(ticks):
            t = self.t + 1
            p_h = e.p_h[rows, t]
            self.v_a = e.blend[rows, t] + self.gain * alpha * self.gap
            self.p_a = self.p_a + self.dt * self.v_a
            reward, inside = step_reward(p_h, self.p_a, e.v_h[rows, t], alpha, self.inside, self._r_in, self._r_exit)
            live = ~self.done
            total += np.where(live, self._discount[j] * reward, 0.0)
            self.discounted_return += np.where(live, self.gamma ** (t - self.interval) * reward, 0.0)
            self.done |= self.inside & ~inside  # leaving the goal set ends the episode
            self.inside = inside
            self.gap = p_h - self.p_a
            self.t = t
        return total

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Hold the actions (indices into :data:`~cogblocks.amplification.corrector.ACTIONS`) for one interval.

        Returns
        -------
        state : numpy.ndarray, shape (B, 13)
            The state at the interval's last tick.
        reward : numpy.ndarray, shape (B,)
            Discounted sum of the interval's rewards (up to the tick that ends an episode).
        done : numpy.ndarray of bool, shape (B,)
            Whether the episode ended during the interval (goal set left, or the last tick reached).
        """
        was_done = self.done.copy()
        ticks = min(self.interval, self.n_steps - 1 - self.t)
        reward = self._advance(ACTIONS[np.asarray(actions)], ticks)
        if self.t >= self.n_steps - 1:
            self.done[:] = True
        reward[was_done] = 0.0
        return self.state(), reward, self.done.copy()

    def final_distance(self) -> np.ndarray:
        """‖p_a − p_h‖ at the current tick, shape (B,)."""
        return np.linalg.norm(self.episodes.p_h[self.rows, self.t] - self.p_a, axis=1)
