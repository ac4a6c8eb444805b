"""PoP of Amplification benchmark: time per decision of the optimisation-based blending.

    python benchmarks/optimal_blending.py [--quick]

Held-out no-fear movements of the shipped encoder's split are replayed through the architecture
in the same run: with the table-lookup :class:`~cogblocks.amplification.VelocityBlender` (the
reference), with :class:`~cogblocks.amplification.OptimalBlender` as ``cogblocks run amplification``
runs it ("realistic": the blender ensemble, the realism subspace and the linearised solver, configured as
``OPTIMISED``), with one network and casadi (8 ms limit; sqpmethod, and IPOPT in the full run) and with the
table lookup plus the
:class:`~cogblocks.amplification.RLCorrector`. A blender's decision is its output on a tick where the
projector's decision count changes: for the table, looking ``c`` up and blending; for the
optimiser, every tick on which it works on a decision: building the problem, solving it (one solve
may span ``solve_ticks`` ticks) and checking the result (decisions after the planned movement has
ended, with nothing to solve, are left out). The corrector's decision is its update on
the ticks where it chooses α (one DQN forward pass). Each decision is timed with the wall clock and
with ``time.thread_time_ns``, the calling thread's CPU time (what the solver's time limit and the
block's own ``solve_ms`` use): on a shared machine the wall clock also counts the slices the
scheduler gives other processes. Prints one JSON object per line, ``ratio = value / reference``; the
optimiser's fallback count is a context key.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable, Iterator

import numpy as np
import torch

from cogblocks.amplification import OptimalBlender, RLCorrector, load_corrector
from cogblocks.diagrams.amplification import _optimal_blender, amplification_setup, pop_amplification
from cogblocks.diagrams.amplification_setup import blender_networks
from cogblocks.sim import Block, Simulator


def _time_calls(
    block: Block,
    method: str,
    decides: Callable[[int], bool],
    log: list[tuple[float, float]],
    worked: Callable[[], int] | None = None,
) -> None:
    """Make ``block.<method>`` append (wall ms, CPU ms) to ``log`` on the ticks where ``decides(k)``
    (and, with ``worked``, where that count grew during the call)."""
    call = getattr(block, method)

    def timed(k: int) -> None:
        if not decides(k):
            call(k)
            return
        before = worked() if worked is not None else 0
        wall, cpu = time.perf_counter_ns(), time.thread_time_ns()
        call(k)
        elapsed = ((time.perf_counter_ns() - wall) / 1e6, (time.thread_time_ns() - cpu) / 1e6)
        if worked is None or worked() > before:
            log.append(elapsed)

    setattr(block, method, timed)  # before compiling: the plan binds the methods then


def _replay(setup, humans: np.ndarray, variant: str) -> tuple[np.ndarray, int]:
    """(wall, CPU) ms of every timed decision of ``variant`` over ``humans``, and the optimiser's fallbacks.

    ``variant``: ``"table"``, ``"rl"`` (the corrector's decisions) or an :class:`OptimalBlender` solver.
    """
    times, fallbacks = [], 0
    network = load_corrector()
    for human in humans:
        if variant == "realistic":  # what `cogblocks run amplification` runs: the blender ensemble, OPTIMISED
            blender = _optimal_blender(setup, blender_networks(setup.encoder))
        elif variant not in ("table", "rl"):
            blender = OptimalBlender(
                setup.movements,
                setup.encoder,
                setup.table,
                solver=variant,
                time_limit_ms=8.0,
                solve_ticks=1,
                iterations=10,
                realism=30.0,
                margin=0.05,
                removal_margin=None,
                emit="human",
                guard_rest=False,
                neighbours=1,
                terminal_margin=5.0,
            )  # the solver comparison's setting, not the shipped one
        else:
            blender = None
        d = pop_amplification(
            (setup.library.velocity[human], setup.library.position[human]),
            setup.movements,
            table=setup.table,
            encoder=setup.encoder,
            blending=blender,
            corrector=RLCorrector(network) if variant == "rl" else None,
        )
        log: list[tuple[float, float]] = []
        if variant == "rl":
            corrector = d["l2.corrector"]
            _time_calls(corrector, "update", lambda k, c=corrector: (k + 1) % c.interval == 0, log)
        elif blender is None:
            block, seen = d["l2.blender"], [0]

            def new_decision(k: int, block: Block = block, seen: list[int] = seen) -> bool:
                changed = int(block.decisions.value) != seen[0]
                seen[0] = int(block.decisions.value)
                return changed

            _time_calls(block, "output", new_decision, log)
        else:  # every tick; kept: those where the block worked on a decision (it records them in tick_ms)
            _time_calls(d["l2.blender"], "output", lambda k: True, log, worked=lambda b=blender: len(b.tick_ms))
        Simulator(d).run(n_steps=setup.library.max_len)
        if blender is not None:
            fallbacks += blender.fallbacks
        times += log
    return np.array(times), fallbacks


def run(quick: bool = False) -> Iterator[dict]:
    """Yield p50/p99 of the time per decision (wall and CPU): the runner's realistic configuration, sqpmethod,
    the RL corrector and (full run) IPOPT."""
    torch.set_num_threads(1)
    setup = amplification_setup()
    humans = setup.humans[:3] if quick else setup.humans
    table, _ = _replay(setup, humans, "table")
    variants = [("realistic", humans), ("sqpmethod", humans), ("rl", humans)] + (
        [] if quick else [("ipopt", humans[:20])]
    )
    for variant, movements in variants:
        measured, fallbacks = _replay(setup, movements, variant)
        for clock, column in (("wall", 0), ("cpu", 1)):
            for q in (50, 99):
                value, reference = np.percentile(measured[:, column], q), np.percentile(table[:, column], q)
                yield {
                    "name": f"optimal_blending.{variant}.{clock}.p{q}",
                    "value": float(value),
                    "unit": "ms",
                    "reference": float(reference),
                    "ratio": float(value / reference),
                    "decisions": len(measured),
                    "movements": len(movements),
                    "fallbacks": fallbacks,
                }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="three movements, no IPOPT")
    args = parser.parse_args(argv)
    for result in run(quick=args.quick):
        print(json.dumps(result), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
