"""Closed loop of the PoP of Social Connectedness, vectorised over a batch of episodes.

A Kuramoto group on a graph (forward Euler, all phases starting at 0 rad), the L2 blender of
eqs. (3)-(6) altering the assisted participant's phase, and the L3 motion computer: a virtual
Kuramoto oscillator at the assisted participant's node whose frequency a policy changes every tick.
At tick ``k`` (``a`` the assisted index):

1. the policy sees ``[angle(q), 1 - |q|, omega_L3[k-1]]`` with
   ``q = mean_{j != a} exp(i wrap_pi(theta_L3[k] - theta_j[k]))`` and picks
   ``omega_L3[k] = clip(omega_L3[k-1] + ACTIONS[action], -15, 15)``, ``omega_L3[-1] = mean(omega)``;
2. the blender gives ``theta_L2[k] = wrap(theta_L0[k] + sat_lambda[k](wrap_pi(theta_L3[k] - theta_L0[k])))``
   with ``theta_L0 = theta_a``, and one Euler step of eq. (6) gives ``lambda[k+1]``;
3. the order parameter ``r[k]`` is taken on ``theta~`` (``theta`` with ``theta~_a = theta_L2[k]``);
4. every participant (the assisted one too) integrates its coupling on ``theta~``, and the virtual
   oscillator integrates its coupling to the neighbours' true phases.

Without L2, ``theta~ = theta``. The figure of merit is the mean of ``r[k]`` over ``k = 0 ... T/dt``.

Since ``theta_L2[k]`` and ``r[k]`` depend on the state at tick ``k`` only (the action of tick ``k``
first moves ``theta_L3[k+1]``), the environment evaluates steps 2-3 on arriving at a tick, and
``step`` returns ``r[k+1]``: the first sample the action can influence."""

from __future__ import annotations

import functools

import numpy as np

from cogblocks.data.groups import SyncGroup
from cogblocks.sync import L3Context, L3Policy
from cogblocks.sync.model import DT, BlenderParams, SyncModel, order_parameter
from cogblocks.sync.motion import ACTIONS, HOLD_ACTION, OMEGA_L3_LIMIT, l3_observation

__all__ = ["SyncEnv", "evaluate", "order_parameter_without_l2"]


class SyncEnv:
    """Batch of closed-loop episodes of the same length, advanced together.

    Parameters
    ----------
    model : SyncModel
        ``model.omega`` of shape (B, N) (and ``model.gain`` scalar or (B,)) gives one episode per row.
    n_steps : int
        Ticks per episode, ``T / dt``; an episode has ``n_steps + 1`` samples of ``r``.

    Attributes
    ----------
    k : int
        Current tick.
    theta, theta_l3, lam, omega_prev : ndarray
        State at tick ``k``: true phases (B, N), virtual oscillator phase (B,), blender threshold (B,),
        L3 frequency of tick ``k - 1`` (B,).
    theta_tilde, alteration, r, observation : ndarray
        Phases the group sees (B, N), ``wrap_pi(theta_L2 - theta_L0)`` (B,), order parameter (B,) and
        policy observations (B, 3) at tick ``k``.
    r_sum, alteration_sum, alteration_max : ndarray
        Running sum of ``r`` and of ``|alteration|``, and largest ``|alteration|``, over ticks ``0 ... k``.
    """

    def __init__(self, model: SyncModel, n_steps: int) -> None:
        if np.ndim(model.omega) != 2:
            raise ValueError("model.omega must have shape (B, N)")
        self.model = model
        self.n_steps = int(n_steps)
        self.batch_size = model.omega.shape[0]
        self._others = model.others
        self.reset()

    @classmethod
    def from_group(
        cls,
        group: SyncGroup,
        batch_size: int = 1,
        *,
        l2: bool = True,
        blender: BlenderParams | None = None,
        dt: float = DT,
    ) -> SyncEnv:
        """``batch_size`` identical episodes of a group (on its graph) over its whole duration."""
        model = SyncModel.from_group(group, l2=l2, blender=blender, dt=dt)
        batched = SyncModel(
            np.tile(model.omega, (batch_size, 1)), model.gain, model.adjacency, model.assisted, model.dt, model.blender
        )
        return cls(batched, round(group.duration / dt))

    @property
    def done(self) -> bool:
        """Whether the last tick, ``n_steps``, has been reached."""
        return self.k >= self.n_steps

    @property
    def mean_order_parameter(self) -> np.ndarray:
        """Figure of merit so far: mean of ``r`` over ticks ``0 ... k``, shape (B,)."""
        return self.r_sum / (self.k + 1)

    def reset(self) -> np.ndarray:
        """Start every episode at tick 0 and return its observations, shape (B, 3)."""
        batch, n = self.batch_size, self.model.n
        self.k = 0
        self.theta = np.zeros((batch, n))
        self.theta_l3 = np.zeros(batch)
        self.lam = np.full(batch, self.model.blender.lam_max if self.model.blender else np.nan)
        self.omega_prev = self.model.omega.mean(axis=-1)
        self.r_sum = np.zeros(batch)
        self.alteration_sum = np.zeros(batch)
        self.alteration_max = np.zeros(batch)
        self._arrive()
        return self.observation

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
        """Apply one action per episode at tick ``k`` and move to tick ``k + 1``.

        Parameters
        ----------
        actions : ndarray of int, shape (B,)
            Indices into :data:`ACTIONS`.

        Returns
        -------
        obs : ndarray, shape (B, 3)
            Observations of tick ``k + 1``.
        reward : ndarray, shape (B,)
            ``r[k + 1]``, the order parameter (with L2 if enabled) the group reaches.
        done : bool
            True once tick ``n_steps`` is reached.
        """
        if self.done:
            raise RuntimeError("episode finished; call reset()")
        omega_l3 = np.clip(self.omega_prev + ACTIONS[np.asarray(actions)], -OMEGA_L3_LIMIT, OMEGA_L3_LIMIT)
        self.theta, self.theta_l3 = self.model.advance(self.theta, self.theta_tilde, self.theta_l3, omega_l3)
        self.lam = self._lam_next
        self.omega_prev = omega_l3
        self.k += 1
        self._arrive()
        return self.observation, self.r, self.done

    def context(self, episode: int = 0) -> L3Context:
        """Everything a single-episode policy may use at the current tick."""
        return L3Context(
            k=self.k,
            obs=self.observation[episode],
            theta=self.theta[episode].copy(),
            theta_l3=float(self.theta_l3[episode]),
            lam=float(self.lam[episode]),
            omega_prev=float(self.omega_prev[episode]),
            assisted=self.model.assisted,
        )

    def _arrive(self) -> None:
        # theta_L2[k] and r[k] depend only on the state of tick k, so they are evaluated once here.
        self.theta_tilde, self.alteration, self._lam_next = self.model.blend(self.theta, self.theta_l3, self.lam)
        self.r = order_parameter(self.theta_tilde)
        self.observation = l3_observation(self.theta_l3, self.theta[:, self._others], self.omega_prev)
        self.r_sum += self.r
        self.alteration_sum += np.abs(self.alteration)
        np.maximum(self.alteration_max, np.abs(self.alteration), out=self.alteration_max)


@functools.cache
def order_parameter_without_l2(group: SyncGroup, dt: float = DT) -> float:
    """Mean order parameter of ``group`` over ticks ``0 ... T/dt`` without L2 (cached: it needs no policy)."""
    env = SyncEnv.from_group(group, l2=False, dt=dt)
    while not env.done:
        env.step(np.array([HOLD_ACTION]))
    return float(env.mean_order_parameter[0])


def evaluate(
    policy: L3Policy, group_params: SyncGroup, l2: bool = True, *, blender: BlenderParams | None = None, dt: float = DT
) -> dict[str, float]:
    """Run one episode of ``group_params`` with ``policy`` as the L3 motion computer.

    Parameters
    ----------
    policy : L3Policy
        Reset with ``mean(omega)``, then asked for one action per tick.
    group_params : SyncGroup
        Group, assisted participant and duration.
    l2 : bool
        Blend the policy's reference into the assisted participant's phase. Without L2 the policy
        cannot influence the group, so ``r_with`` equals ``r_without``.
    blender : BlenderParams, optional
        Defaults to the deliverable's parameters.
    dt : float
        Euler step (s).

    Returns
    -------
    dict
        ``r_without`` and ``r_with`` (mean order parameter over ticks ``0 ... T/dt``), ``change_pct``
        (relative change in %), ``alteration_mean`` and ``alteration_max`` (``|wrap_pi(theta_L2 - theta_L0)|``
        in rad, averaged over ticks and largest).
    """
    env = SyncEnv.from_group(group_params, l2=l2, blender=blender, dt=dt)
    policy.reset(float(env.omega_prev[0]))
    while not env.done:
        env.step(np.array([policy.act(env.context())]))
    r_without = order_parameter_without_l2(group_params, dt)
    r_with = float(env.mean_order_parameter[0])
    return {
        "r_without": r_without,
        "r_with": r_with,
        "change_pct": 100.0 * (r_with - r_without) / r_without,
        "alteration_mean": float(env.alteration_sum[0] / (env.k + 1)),
        "alteration_max": float(env.alteration_max[0]),
    }
