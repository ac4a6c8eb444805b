import json

from cogblocks.data.groups import random_groups
from cogblocks.diagrams.sync import pop_sync
from cogblocks.sim import Simulator
from cogblocks.sync.gated import GatedMotion
from cogblocks.sync.motion import MeanPhaseMotion

out = []
for noisy in (False, True):
    for g in random_groups(16, "validation", 0, noise=noisy):
        m = GatedMotion(MeanPhaseMotion(g.n, g.assisted), adjacency=g.graph)
        sim = Simulator(pop_sync(g, motion=m))
        sim.run(n_steps=201)
        out.append(
            {
                "noisy": noisy,
                "sigma_hat": sim.compiled.blocks["l2.motion.gate"].sigma_hat,
                "sigma_mean": None if g.noise is None else sum(g.noise.sigma) / g.n,
            }
        )
print(json.dumps(out))
