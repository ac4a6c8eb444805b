"""Phase locking of the Table 2 groups, eigenvalues of a locked group, and linearize() on a diagram.

Writes linearize_kuramoto.png into FOLDER (default: the working directory); the figure of docs/ is made with

    python examples/linearize_kuramoto.py docs/img
"""

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from cogblocks.analysis import kuramoto_linearization, linearize
from cogblocks.data.groups import TABLE2  # noqa: E402
from cogblocks.sim import Diagram  # noqa: E402
from cogblocks.sync import KuramotoGroup

for gid, group in TABLE2.items():
    print(f"Group {gid} (gain {group.gain:.4g}): {kuramoto_linearization(group.omega, group.gain).message}")

# Group 3 with a little more coupling than Table 2's 4.4/7 locks
g3 = TABLE2[3]
locked = kuramoto_linearization(g3.omega, 0.8)
print(f"\nGroup 3 at gain 0.8:\n{locked}")

# the same Jacobian from finite differences of the compiled diagram's one-tick map
d = Diagram()
group = d.add("group", KuramotoGroup(g3.omega, 0.8, theta0=locked.phases))
d.expose_output("theta", group.theta)
d.compile(0.01)
linear = linearize(d)
print(f"max |A_linearize − (I + dt J)| = {np.abs(linear.A - locked.discrete.A).max():.2e}")

# Group 3 against the gain: the smallest gain that locks, and the spectrum of the locked state
low, high = g3.gain, 0.8
for _ in range(30):
    mid = 0.5 * (low + high)
    low, high = (low, mid) if kuramoto_linearization(g3.omega, mid).locked else (mid, high)
print(f"Group 3 locks from gain {high:.5f} (= {7 * high:.4f}/7); Table 2 uses {g3.gain:.5f} (= 4.4/7)")

gains = np.linspace(0.6, 1.5, 91)
results = [kuramoto_linearization(g3.omega, k) for k in gains]
locked_at = np.array([r.locked for r in results])
rates = np.array([np.nan if r.rate is None else r.rate for r in results])

fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4))
ax1.plot(gains[locked_at], rates[locked_at], ".-", label="stable locked state: rate")
ax1.plot(gains[~locked_at], rates[~locked_at], "x", color="0.5", label="no stable lock: least unstable locked state")
ax1.axhline(0.0, color="k", lw=0.8)
ax1.axvline(g3.gain, color="C3", ls="--", label=f"Table 2 gain 4.4/7 = {g3.gain:.3f}")
ax1.axvline(high, color="C2", ls=":", label=f"locks from gain {high:.3f}")
ax1.set(xlabel="gain", ylabel="largest non-zero eigenvalue (1/s)", title="Group 3 (ring of 7): local convergence rate")
ax1.legend(fontsize=8)
spectra = np.array([r.eigenvalues.real for r in results if r.locked])
ax2.plot(gains[locked_at], spectra[:, 1:], color="C0")
ax2.plot(gains[locked_at], spectra[:, 0], color="k", lw=0.8, label="0: common rotation")
ax2.axvline(high, color="C2", ls=":")
ax2.set(xlabel="gain", ylabel="eigenvalues of J (1/s)", title="Group 3 locked: spectrum of J")
ax2.legend(fontsize=8)
fig.tight_layout()

out = Path(sys.argv[1] if len(sys.argv) > 1 else ".") / "linearize_kuramoto.png"
fig.savefig(out, dpi=110)
print(f"wrote {out}")
