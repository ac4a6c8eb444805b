"""σ̂ of the gate on the 16 first validation groups, noise-free and noisy (the gate around the circular mean, 20 s).

python studies/noisy_gate_check.py > studies/noisy-validation/gate_sigma_hat.json

Per group: the first decision's σ̂ (after ``DECIDE_AFTER`` s), the largest σ̂ of every later check, the world found.
"""

import dataclasses
import json

from cogblocks.data.groups import random_groups
from cogblocks.diagrams.sync import pop_sync
from cogblocks.sim import Simulator
from cogblocks.sync.gated import DECIDE_AFTER, GatedMotion
from cogblocks.sync.motion import MeanPhaseMotion

out = []
for noisy in (False, True):
    for g in random_groups(16, "validation", 0, noise=noisy):
        g = dataclasses.replace(g, duration=min(g.duration, 20.0))
        m = GatedMotion(MeanPhaseMotion(g.n, g.assisted), adjacency=g.graph)
        sim = Simulator(pop_sync(g, motion=m))
        ticks = round(DECIDE_AFTER / 0.01)
        sim.run(n_steps=ticks)
        first, largest = m.sigma_hat, m.sigma_hat
        while ticks < round(g.duration / 0.01) + 1:
            sim.run(n_steps=100)
            ticks += 100
            largest = max(largest, m.sigma_hat)
        sigma = None if g.noise is None else sum(g.noise.sigma) / g.n
        out.append({"noisy": noisy, "first": first, "largest": largest, "world": m.world, "sigma_mean": sigma})
print(json.dumps(out))
