"""PoP of Social Connectedness: Table 3 and Figures 9-10 for Group 1, then a swapped blender.

Writes pop_sync_group1.png into the folder given as the first argument (default: the working directory)::

    python examples/pop_sync.py [FOLDER]
"""

import sys
from pathlib import Path

from cogblocks.diagrams.sync import plot_sync, pop_sync, run_sync
from cogblocks.sim import Simulator
from cogblocks.sync import Blender

result = run_sync(1)
print(f"Group 1 without L2: {result['r_without']:.3f}")
for row in result["results"]:
    change, deviation = row["change_pct"], row["max_dev_rad"]
    print(f"  {row['policy']:>10}: {row['r_with']:.3f} ({change:+.2f} %), max |θ_L2 − θ_L0| {deviation:.2f} rad")
figure = Path(sys.argv[1] if len(sys.argv) > 1 else ".") / "pop_sync_group1.png"
plot_sync(1, "mean", figure)
print(f"wrote {figure}")

# swapping one block of the L2 architecture is one call
d = pop_sync(1, motion="mean")
d.replace("l2.blender", Blender(saturation="smooth", psi="bump"))
r = Simulator(d).run(n_steps=1001)["r"]
print(f"  smooth saturation + bump ψ: {r.mean():.3f}")
