"""PoP of Amplification: a held-out no-fear reach made to encode fear, then the RL corrector swapped in.

Writes pop_amplification_fig6.png into the folder given as the first argument (default: the working directory)::

    python examples/pop_amplification.py [FOLDER]
"""

import sys
from pathlib import Path

import numpy as np

from cogblocks.amplification import RLCorrector
from cogblocks.diagrams.amplification import amplification_setup, plot_amplification, pop_amplification
from cogblocks.sim import Simulator

# the shipped encoder, the split it was validated on, and w̃ on the training part (computed once, then cached)
setup = amplification_setup()
human = int(setup.humans[0])
movement = (setup.library.velocity[human], setup.library.position[human])
print(f"library of {len(setup.movements)} movements, {len(setup.humans)} held-out no-fear movements to alter")

d = pop_amplification(movement, setup.movements, table=setup.table, encoder=setup.encoder)
probes = {"decision": "encoder.decision", "reference": "l2.reference"}
trace = Simulator(d, probes=probes).run(n_steps=setup.library.max_len)
print(
    f"movement {human}: reference {int(trace['reference'][-1])}, c from {trace['c'][10]:.2f} to "
    f"{trace['c'][-1]:.2f}, final ε̂ {trace['eps'][-1]:.2f} (decision {int(trace['decision'][-1])}), "
    f"final distance {np.linalg.norm(trace['p_a'][-1] - trace['p_h'][-1]):.1f} mm"
)

# the corrector is one swappable block of the architecture
d.replace("l2.corrector", RLCorrector())
trace = Simulator(d, probes=probes).run(n_steps=setup.library.max_len)
print(
    f"with the RL corrector: final ε̂ {trace['eps'][-1]:.2f}, "
    f"final distance {np.linalg.norm(trace['p_a'][-1] - trace['p_h'][-1]):.1f} mm"
)

figure = Path(sys.argv[1] if len(sys.argv) > 1 else ".") / "pop_amplification_fig6.png"
plot_amplification(figure)
print(f"wrote {figure}")
