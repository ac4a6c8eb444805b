"""Stability of the Blender's λ dynamics: λ∞(λ) against the bisector, and λ(t) with its settling times.

Writes analysis_lambda.png into FOLDER (default: the working directory); the figure of docs/ is made with

    python examples/analysis_lambda.py docs/img
"""

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from cogblocks.blocks import Playback
from cogblocks.sim import Diagram, Simulator  # noqa: E402
from cogblocks.sync import Blender, check_blender, lambda_report

DT = 0.01
N_FAR, N_BACK = 400, 600  # reference far away for 4 s, then back on θ_L0 for 6 s

report = check_blender(Blender(), DT)
print(report)
print(lambda_report(Blender(psi="bump"), DT))
steep = Blender(lam_min=0.2, lam_max=1.0, e_max=0.8)  # λ* below e_max, on the sloped piece of ψ
print(lambda_report(steep, DT))

# simulate the block: θ_L0 = 0, θ_ref = 2.5 rad (beyond λ_max), then θ_ref = θ_L0
d = Diagram()
l0 = d.add("l0", Playback(np.zeros(N_FAR + N_BACK), unit="rad", wrapped=True))
ref = d.add("ref", Playback(np.r_[np.full(N_FAR, 2.5), np.zeros(N_BACK)], unit="rad", wrapped=True))
bl = d.add("bl", Blender())
d.connect(l0.y, bl.theta_l0)
d.connect(ref.y, bl.theta_ref)
trace = Simulator(d, dt=DT, probes=["bl.lam"]).run(n_steps=N_FAR + N_BACK)

fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4))
lam = np.linspace(0.0, 1.05 * report.lam_max, 500)
for blender, style in ((Blender(), "-"), (Blender(psi="bump"), "--"), (steep, ":")):
    label = f"λ∞(λ), {blender.psi}" + (", steep" if blender is steep else "")
    ax1.plot(lam, [blender.lam_inf(x) for x in lam], style, label=label)
    star = lambda_report(blender, DT).lam_star
    ax1.plot(star, star, "ko", ms=4)
ax1.plot(lam, lam, "k", lw=0.8, label="bisector λ∞ = λ")
ax1.annotate(
    f"deliverable λ* = {report.lam_star:.3f}",
    (report.lam_star, report.lam_star),
    (0.7, 0.3),
    arrowprops={"arrowstyle": "->"},
)
ax1.set(xlabel="λ = e (rad)", ylabel="λ∞ (rad)", title="Equilibrium at the limit (e = λ)")
ax1.legend(fontsize=8)

t = trace.t
band = report.tolerance * (report.lam_max - report.lam_star)
ax2.plot(t, trace["bl.lam"], label="λ(t), simulated")
ax2.axhspan(report.lam_star - band, report.lam_star + band, color="C1", alpha=0.2, label="2 % bands")
ax2.axhspan(report.lam_max - band, report.lam_max + band, color="C1", alpha=0.2)
ax2.axvline(report.settle_down, color="C3", ls="--", label=f"settled down: {report.settle_down:.2f} s")
ax2.axvline(N_FAR * DT + report.settle_up, color="C2", ls="--", label=f"settled up: +{report.settle_up:.2f} s")
ax2.axvline(N_FAR * DT, color="k", lw=0.8)
ax2.set(xlabel="t (s)", ylabel="λ (rad)", title="θ_ref far from θ_L0 until 4 s, then on it")
ax2.legend(fontsize=8)
fig.tight_layout()

out = Path(sys.argv[1] if len(sys.argv) > 1 else ".") / "analysis_lambda.png"
fig.savefig(out, dpi=110)
print(f"wrote {out}")
