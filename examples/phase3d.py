"""3D phase estimation: estimate the phase of a hand trajectory online, then drive an avatar from it.

Writes phase3d_figure14.png into the folder given as the first argument (default: the working directory)::

    python examples/phase3d.py [FOLDER]
"""

import sys
from pathlib import Path

from cogblocks.data.motion3d import generate_motion3d
from cogblocks.diagrams.phase3d import phase3d_accuracy, phase_chain, plot_phase3d
from cogblocks.sim import Simulator

accuracy = phase3d_accuracy(n_trajectories=5, seed=0)
print(f"online vs truth: mean {accuracy['mean_error_rad']:.3f} rad, p95 {accuracy['p95_error_rad']:.3f} rad")
figure = Path(sys.argv[1] if len(sys.argv) > 1 else ".") / "phase3d_figure14.png"
plot_phase3d(figure, seed=0)
print(f"wrote {figure}")

motion = generate_motion3d(seed=3, duration=20.0)
diagram = phase_chain(motion, avatar_noise_mm=1.0)
trace = Simulator(diagram, probes={"valid": "estimator.valid"}).run(n_steps=len(motion.t))
print(f"group synchrony with the avatar once the phase is known: {trace['r'][trace['valid']].mean():.3f}")
print("avatar's last position [mm]:", trace["avatar_p"][-1].round(1))
