"""How wrong the online identification of a group is, over time, against the group's true (drifting) values.

:func:`identification_errors` runs a group without L2 (its noisy plant when it has noise), feeds every tick to
:class:`~cogblocks.sync.identification.KuramotoRLS` as the motion computers do, and compares the estimate with
the truth: the frequencies in force at that tick (``ω_i + δ_i(t)``, the plant's drift) and the coupling gain.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cogblocks.blocks import Probe
from cogblocks.data.groups import SyncGroup
from cogblocks.sim import Diagram, Simulator
from cogblocks.sync.group import KuramotoGroup
from cogblocks.sync.identification import KuramotoRLS
from cogblocks.sync.model import DT

__all__ = ["identification_errors"]


def identification_errors(
    group: SyncGroup,
    *,
    forgetting: float = 1.0,
    omega_forgetting: float | None = None,
    duration: float | None = None,
    every: float = 1.0,
) -> dict[str, Any]:
    """ω and K errors of the identification over a run of ``group`` without L2.

    Parameters
    ----------
    group : SyncGroup
        The group; its noise (``group.noise``) if it has some.
    forgetting, omega_forgetting : float
        :class:`~cogblocks.sync.identification.KuramotoRLS`' forgetting factors (the motion computers use 1).
    duration : float, optional
        Seconds; the group's by default.
    every : float
        Seconds between the reported samples.

    Returns
    -------
    dict
        ``"t"`` (s), ``"omega_rms"`` (rad/s: RMS over the participants of ω̂_i − ω_i(t), the true frequency in
        force), ``"omega_drift_rms"`` (how far the true frequencies have drifted from the group's, for scale),
        ``"gain_error"`` (K̂ − K) at those times, and their means over the run's second half:
        ``"omega_rms_late"``, ``"gain_abs_error_late"``.
    """
    duration = group.duration if duration is None else float(duration)
    n_steps = round(duration / DT)
    plant = KuramotoGroup.for_group(group, assisted=False)
    d = Diagram()
    d.add("group", plant)
    d.add("theta", Probe())
    d.connect("group.theta", "theta.u")
    theta = Simulator(d).run(n_steps=n_steps + 1)["theta"]
    true_omega = np.asarray(group.omega, dtype=float) + plant.drift_path(n_steps + 1, DT)
    rls = KuramotoRLS(group.adjacency(), forgetting=forgetting, omega_forgetting=omega_forgetting)
    stride = max(1, round(every / DT))
    rows = []
    for k in range(n_steps):
        rls.observe(theta[k], theta[k], theta[k + 1], DT)
        if (k + 1) % stride == 0:
            omega, gain = rls.estimate()  # after tick k + 1's increment: the frequencies of tick k
            rows.append(
                (
                    (k + 1) * DT,
                    float(np.sqrt(np.mean((omega - true_omega[k]) ** 2))),
                    float(np.sqrt(np.mean((true_omega[k] - np.asarray(group.omega)) ** 2))),
                    gain - group.gain,
                )
            )
    t, omega_rms, drift_rms, gain_error = (np.array(column) for column in zip(*rows, strict=True))
    late = t > duration / 2
    return {
        "t": t,
        "omega_rms": omega_rms,
        "omega_drift_rms": drift_rms,
        "gain_error": gain_error,
        "omega_rms_late": float(omega_rms[late].mean()),
        "gain_abs_error_late": float(np.abs(gain_error[late]).mean()),
    }
