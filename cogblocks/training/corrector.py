"""Train the RL corrector of the PoP of Amplification (appendix paper, sections IV and V-C) with DQN.

Usage::

    python -m cogblocks.training.corrector --seed 0 [--episodes 1100] [--out corrector.pt]

The checkpoint goes to ``--out``, by default ``corrector.pt`` in the working directory: the weights
shipped with the package (``cogblocks/data/weights/corrector.pt``) are replaced only when ``--out``
names them.

The settings of the notes: a :class:`~cogblocks.amplification.CorrectorNet` (two hidden layers of 128
ReLU units, 8 actions), discount 0.99 per tick, Adam with learning rate 1e-3, ε-greedy exploration
from ε = 1 multiplied by 0.995 after each episode (floor 0.001, as in the prototype), the target
network copied after each episode, 1100 episodes of 200 ticks. Each episode replays one no-fear
movement of the training part of the encoder's split, drawn at random, through the architecture
(:mod:`cogblocks.training.amplification_env`; the replayed movement is left out of the projector's
library); its reference, w̃ and horizon are those of the online architecture. The reward is
(16)–(17) with ``k_s = max(length(v_h), length(v_r))``.

The corrector decides every 10 ticks, so a transition is one decision: the discounted sum of the
10 per-tick rewards, bootstrapped with ``γ^10`` (the semi-Markov form of DQN). Leaving the goal set
and the end of the window end an episode. Rewards are scaled by ``reward_scale`` for the regression
(it does not change the greedy policy). Every ``eval_every`` episodes the greedy policy is run on all
training movements and the network with the best mean discounted return is kept.

Everything is seeded (``torch.manual_seed`` for the weights, one NumPy generator for the movement
draws, exploration and replay) and runs on one thread, so a seed reproduces the weights exactly.
"""

from __future__ import annotations

import argparse
import copy
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from cogblocks.amplification import CorrectorNet
from cogblocks.amplification.corrector import ACTIONS, STATE_SIZE
from cogblocks.amplification.solution import library_fingerprint
from cogblocks.diagrams.amplification import DELTA_POS_MM, amplification_setup
from cogblocks.training.amplification_env import AmplificationEnv, Episodes, record_episodes
from cogblocks.training.dqn import DQNLearner, ReplayBuffer

__all__ = ["CorrectorConfig", "TrainingResult", "evaluate", "main", "train"]

DEFAULT_OUT = Path("corrector.pt")  # in the working directory, never the shipped weights by default
SHIPPED = Path(__file__).resolve().parent.parent / "data" / "weights" / "corrector.pt"


@dataclass(frozen=True)
class CorrectorConfig:
    """Hyper-parameters of :func:`train` (the notes' values where they give one).

    Attributes
    ----------
    episodes : int
        Training episodes (one movement each).
    gamma : float
        Discount per tick.
    learning_rate : float
        Adam step size.
    eps_start, eps_decay, eps_min : float
        ε-greedy exploration: ε starts at ``eps_start`` and is multiplied by ``eps_decay`` after each
        episode, down to ``eps_min``.
    batch_size : int
        Transitions per gradient step.
    buffer_size : int
        Replay capacity in transitions.
    learning_starts : int
        Transitions stored before the first gradient step.
    updates_per_decision : int
        Gradient steps after each decision.
    reward_scale : float
        Factor on the rewards for the regression.
    max_grad_norm : float
        Gradient-norm clipping.
    eval_every : int
        Episodes between two evaluations of the greedy policy.
    """

    episodes: int = 1100
    gamma: float = 0.99
    learning_rate: float = 1e-3
    eps_start: float = 1.0
    eps_decay: float = 0.995
    eps_min: float = 0.001
    batch_size: int = 128
    buffer_size: int = 100_000
    learning_starts: int = 256
    updates_per_decision: int = 4
    reward_scale: float = 1e-3
    max_grad_norm: float = 10.0
    eval_every: int = 50


@dataclass
class TrainingResult:
    """Outcome of :func:`train`: the selected network and one record per evaluation."""

    network: CorrectorNet
    history: list[dict]
    best_episode: int


def evaluate(network: CorrectorNet, episodes: Episodes, *, gamma: float = 0.99) -> dict[str, float]:
    """Run the greedy policy on every recorded movement at once.

    Returns
    -------
    dict
        ``return`` (mean discounted return from the first decision), ``terminal_ok`` (share ending
        within 20 mm of the human) and ``final_distance_mm`` (mean).
    """
    env = AmplificationEnv(episodes, gamma=gamma)
    state = env.reset(np.arange(len(episodes)))
    done = np.zeros(len(episodes), dtype=bool)
    while not done.all():
        state, _, done = env.step(network.act(state))
    # an episode that left the goal set stopped counting; its position keeps evolving to the window's end
    distance = env.final_distance()
    return {
        "return": float(env.discounted_return.mean()),
        "terminal_ok": float(np.mean(distance <= DELTA_POS_MM)),
        "final_distance_mm": float(distance.mean()),
    }


def train(
    config: CorrectorConfig, seed: int, episodes: Episodes, *, log: Callable[[str], None] | None = print
) -> TrainingResult:
    """Train a :class:`CorrectorNet` with DQN on recorded movements; see the module docstring.

    Parameters
    ----------
    config : CorrectorConfig
        Hyper-parameters.
    seed : int
        Seeds the weights and the NumPy generator of draws, exploration and replay.
    episodes : Episodes
        The training movements (:func:`~cogblocks.training.amplification_env.record_episodes`).
    log : callable, optional
        Receives one line per evaluation; ``None`` is silent.
    """
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    learner = DQNLearner(CorrectorNet(), learning_rate=config.learning_rate, max_grad_norm=config.max_grad_norm)
    online = learner.online
    replay = ReplayBuffer(config.buffer_size, STATE_SIZE)
    env = AmplificationEnv(episodes, gamma=config.gamma)
    bootstrap = config.gamma**env.interval
    epsilon = config.eps_start
    history: list[dict] = []
    best_return, best_state, best_episode = -np.inf, copy.deepcopy(online.state_dict()), 0
    started = time.perf_counter()
    for episode in range(1, config.episodes + 1):
        state = env.reset(rng.integers(len(episodes), size=1))
        done = False
        while not done:
            if rng.random() < epsilon:
                action = int(rng.integers(len(ACTIONS)))
            else:
                action = int(online.act(state)[0])
            next_state, reward, ended = env.step(np.array([action]))
            done = bool(ended[0])
            replay.add(state, np.array([action]), config.reward_scale * reward, next_state, ended)
            state = next_state
            if replay.size >= config.learning_starts:
                for _ in range(config.updates_per_decision):
                    learner.update(replay.sample(rng, config.batch_size), bootstrap)
        learner.update_target()
        epsilon = max(config.eps_min, epsilon * config.eps_decay)
        if episode % config.eval_every == 0 or episode == config.episodes:
            record = {"episode": episode, "epsilon": epsilon, **evaluate(online, episodes, gamma=config.gamma)}
            history.append(record)
            if record["return"] > best_return:
                best_return, best_state, best_episode = record["return"], copy.deepcopy(online.state_dict()), episode
            if log is not None:
                log(
                    f"episode {episode}/{config.episodes}  eps {epsilon:.3f}  return {record['return']:.0f}  "
                    f"terminal ok {record['terminal_ok']:.2f}  distance {record['final_distance_mm']:.1f} mm  "
                    f"({time.perf_counter() - started:.0f} s)"
                )
    online.load_state_dict(best_state)
    online.eval()
    return TrainingResult(network=online, history=history, best_episode=best_episode)


def training_episodes(seed: int | None = None) -> Episodes:
    """The no-fear movements of the training part of the encoder's split, recorded (leave-one-out)."""
    setup = amplification_setup(seed, 1)
    humans = np.flatnonzero(~setup.movements.fear)
    return record_episodes(setup.movements, setup.table, humans)


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m cogblocks.training.corrector",
        description="Train the RL corrector of the PoP of Amplification (DQN, terminal-position constraint).",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of weights, draws, exploration, replay (default 0)")
    parser.add_argument(
        "--episodes",
        type=int,
        default=CorrectorConfig.episodes,
        help=f"training episodes of 200 ticks (default {CorrectorConfig.episodes})",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=DEFAULT_OUT,
        help=f"checkpoint to write (default {DEFAULT_OUT} in the working directory; the shipped one is {SHIPPED})",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> None:
    """Command-line entry point: record the movements, train, save the selected network."""
    args = _parser().parse_args(argv)

    torch.set_num_threads(1)
    started = time.perf_counter()
    episodes = training_episodes()
    print(f"recorded {len(episodes)} training movements in {time.perf_counter() - started:.0f} s")
    config = CorrectorConfig(episodes=args.episodes)
    result = train(config, args.seed, episodes)
    best = next(r for r in result.history if r["episode"] == result.best_episode)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    library_sha256 = library_fingerprint(amplification_setup(None, 1).library)
    torch.save(
        {
            "state_dict": result.network.state_dict(),
            "seed": args.seed,
            "config": asdict(config),
            "library_sha256": library_sha256,
            "best_episode": result.best_episode,
            "history": result.history,
        },
        args.out,
    )
    print(
        f"saved the network of episode {result.best_episode} (return {best['return']:.0f}, terminal ok "
        f"{best['terminal_ok']:.2f}) to {args.out.resolve()} after {time.perf_counter() - started:.0f} s"
    )


if __name__ == "__main__":
    main()
