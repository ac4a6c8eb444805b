"""Where the default planner's decisions spend their time: a cProfile of its first seconds on a large group.

The planner ``replan`` (:class:`~cogblocks.sync.receding.RecedingPlanMotion`) runs on the largest of the first 20
validation groups (N = 15, all-to-all) stretched to a ``--duration`` s trial, so that every decision plans that
far ahead, for ``--seconds`` simulated seconds (its first decision and one per second after it). Printed: each
decision's CPU time (``decide_ms``, the planner's own thread-time record) and the functions that took the most
time, by own time and by cumulative time.

    python -m studies.planner_profile --duration 300 --seconds 8 --top 20
"""

from __future__ import annotations

import argparse
import cProfile
import dataclasses
import io
import pstats

from cogblocks.data.groups import random_groups
from cogblocks.diagrams.sync import pop_sync
from cogblocks.sim import BASE_STEP, Simulator


def profile(duration: float, seconds: float) -> tuple[list[float], pstats.Stats]:
    """The decisions' CPU milliseconds and the profile of ``seconds`` simulated seconds."""
    group = max(random_groups(20, "validation", 0), key=lambda g: g.n)
    group = dataclasses.replace(group, duration=duration)
    diagram = pop_sync(group, motion="replan")
    simulator = Simulator(diagram, progress=False)
    profiler = cProfile.Profile()
    profiler.enable()
    simulator.run(n_steps=round(seconds / BASE_STEP) + 1)
    profiler.disable()
    return list(diagram["l2.motion"].decide_ms), pstats.Stats(profiler)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=300.0, help="the trial's length, s (default 300)")
    parser.add_argument("--seconds", type=float, default=8.0, help="simulated seconds profiled (default 8)")
    parser.add_argument("--top", type=int, default=20, help="functions listed per ordering (default 20)")
    args = parser.parse_args(argv)
    decide_ms, stats = profile(args.duration, args.seconds)
    print("decide_ms:", ", ".join(f"{ms:.0f}" for ms in decide_ms))
    for order in ("tottime", "cumulative"):
        text = io.StringIO()
        stats.stream = text
        stats.sort_stats(order).print_stats(args.top)
        print(text.getvalue())


if __name__ == "__main__":
    main()
