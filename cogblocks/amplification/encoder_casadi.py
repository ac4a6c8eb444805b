"""The encoder network as a casadi function and the solver of Problem (13) built on it."""

from __future__ import annotations

import hashlib
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from cogblocks.amplification.encoder import (
    N_POINTS,
    EncoderNet,
    resampling_matrix,
)
from cogblocks.sim.params import positive_int

__all__ = ["encoder_to_casadi", "ensemble_logits", "input_map", "solve_decision"]

_U_SCALE = 100.0  # mm/s: knots are solved in units of 100 mm/s, so that they are of order one
_PENALTY = 1e3  # weight of the encoding slack (per logit unit) against the correction's cost


def encoder_to_casadi(network: EncoderNet, *, logit: bool = False, sharpness: float | None = None) -> ca.Function:
    """The encoding network ε̂ as a casadi function of its 60 inputs, weights exported from torch.

    The network is taken in evaluation mode (dropout is the identity):
    ``ε̂ = sigmoid(w₂·relu(W₁ (x − mean)/scale + b₁) + b₂)``, in double precision.

    Parameters
    ----------
    network : EncoderNet
        The trained classifier.
    logit : bool
        Return the pre-sigmoid output ``z`` (ε̂ = sigmoid(z)) instead of ε̂: the form used in
        constraints, since ``ε̂ ≥ 0.9`` is ``z ≥ ln 9`` and the sigmoid's flat tails do not slow a
        solver down.
    sharpness : float, optional
        Replace ``relu(y)`` by the softplus ``max(y, 0) + log(1 + exp(−β|y|))/β``, β =
        ``sharpness`` (above ``relu`` by at most ln 2/β): a smooth model of the network for
        Newton-type solvers, which cycle on the kinks of the exact one.

    Returns
    -------
    casadi.Function
        ``x (60) → ε̂`` (or ``z``), named ``"encoder"``; callable on numbers and on MX symbols.
    """
    if not isinstance(network, EncoderNet):
        raise ValueError(f"encoder_to_casadi: network must be an EncoderNet, got {type(network).__name__}")
    w = _weights(network)
    x = ca.MX.sym("x", len(w["mean"]))
    pre = ca.mtimes(ca.DM(w["w1"]), (x - ca.DM(w["mean"])) / ca.DM(w["scale"])) + ca.DM(w["b1"])
    hidden = ca.fmax(0, pre)
    if sharpness is not None:
        hidden = hidden + ca.log1p(ca.exp(-sharpness * ca.fabs(pre))) / sharpness
    z = ca.dot(ca.DM(w["w2"]), hidden) + w["b2"]
    return ca.Function("encoder", [x], [z if logit else 1 / (1 + ca.exp(-z))], ["x"], ["logit" if logit else "eps"])


def input_map(length: int, n_points: int = N_POINTS) -> np.ndarray:
    """The classifier input as a linear map of a movement's samples, for one restricted length.

    Cubic-spline resampling on fixed abscissae is linear in the data, so its matrix is obtained by
    resampling unit vectors with :func:`cogblocks.data.features.resample_movement`
    (:func:`cogblocks.amplification.encoder.resampling_matrix`, shared with w̃ and the online classifier);
    one copy per axis gives the 60 inputs.

    Parameters
    ----------
    length : int
        Samples of the restricted movement (≥ 1).
    n_points : int
        Resampled points per axis.

    Returns
    -------
    numpy.ndarray, shape (3·n_points, 3·length)
        ``inputs = M @ velocity[:length].T.reshape(-1)``, axis-major on both sides as
        ``resample_movement`` returns its points.
    """
    length = positive_int("input_map", "length", length)
    return np.kron(np.eye(3), resampling_matrix(length, n_points))


def _weights(network: EncoderNet) -> dict[str, Any]:
    state = {k: v.detach().double().cpu().numpy() for k, v in network.state_dict().items()}
    return {
        "mean": state["mean"],
        "scale": state["scale"],
        "w1": state["hidden.weight"],
        "b1": state["hidden.bias"],
        "w2": state["out.weight"][0],
        "b2": float(state["out.bias"][0]),
    }


def _weights_key(*weights: dict[str, Any]) -> str:
    digest = hashlib.sha256()
    for member in weights:
        for name in sorted(member):
            digest.update(name.encode())
            digest.update(np.ascontiguousarray(member[name], dtype=np.float64).tobytes())
    return digest.hexdigest()


class _Deadline(ca.Callback):
    """Iteration callback that stops casadi's SQP before an iteration that would end past the deadline.

    Time is the calling thread's CPU time (``time.thread_time``): a solve is not cut short for the
    time the scheduler gave other processes. An iteration is predicted to take as long as the
    previous one (the first, as long as the set-up before it), so a solve ends within about one
    iteration's jitter of the limit.
    """

    def __init__(self, sizes: dict[str, int]) -> None:
        ca.Callback.__init__(self)
        self.sizes = sizes
        self.deadline = self.last = math.inf
        self.construct("optimal_blending_deadline", {})

    def start(self, limit: float) -> None:
        """Arm the deadline ``limit`` seconds of CPU time from now, for the next solve."""
        self.last = time.thread_time()
        self.deadline = self.last + limit

    def get_n_in(self) -> int:
        return ca.nlpsol_n_out()

    def get_n_out(self) -> int:
        return 1

    def get_name_in(self, i: int) -> str:
        return ca.nlpsol_out(i)

    def get_name_out(self, i: int) -> str:
        return "stop"

    def get_sparsity_in(self, i: int) -> ca.Sparsity:
        return ca.Sparsity.dense(self.sizes[ca.nlpsol_out(i)])

    def eval(self, arg: list) -> list:
        now = time.thread_time()
        step, self.last = now - self.last, now
        return [1 if now + step > self.deadline else 0]


@dataclass
class _Solver:
    function: ca.Function
    deadline: _Deadline | None  # sqpmethod only: IPOPT has its own time limit


# Built once per (network, knots per axis, settings) and shared by every block: a validation run
# makes a block per movement, and building a solver takes about 10 ms.
_SOLVERS: dict[tuple, _Solver] = {}


def ensemble_logits(networks: Sequence[EncoderNet], sharpness: float | None = None) -> ca.Function:
    """The logits of several encoder networks at once, ``x (60) → z (members)``, as one casadi function.

    Each network's input normalisation is folded into its first layer and the layers are stacked,
    so the members cost one matrix product (instead of one function call each) inside a solver.
    ``sharpness`` smooths ReLU as in :func:`encoder_to_casadi`.
    """
    weights = [_weights(network) for network in networks]
    w1 = np.vstack([w["w1"] / w["scale"] for w in weights])
    b1 = np.concatenate([w["b1"] - (w["w1"] / w["scale"]) @ w["mean"] for w in weights])
    w2 = np.zeros((len(weights), len(b1)))
    start = 0
    for k, w in enumerate(weights):
        w2[k, start : start + len(w["w2"])] = w["w2"]
        start += len(w["w2"])
    x = ca.MX.sym("x", w1.shape[1])
    pre = ca.mtimes(ca.DM(w1), x) + ca.DM(b1)
    hidden = ca.fmax(0, pre)
    if sharpness is not None:
        hidden = hidden + ca.log1p(ca.exp(-sharpness * ca.fabs(pre))) / sharpness
    z = ca.mtimes(ca.DM(w2), hidden) + ca.DM([w["b2"] for w in weights])
    return ca.Function("ensemble", [x], [z], ["x"], ["logits"])


def _solver(
    networks: Sequence[EncoderNet], key: str, m: int, method: str, time_limit: float, sharpness: float
) -> _Solver:
    """The parametric NLP of one decision with ``m`` decision variables (see :class:`OptimalBlender`).

    The variables ``w`` enter linearly everywhere but in the networks: the classifier input is
    ``x0 + A w``, the cost ``wᵀ H w + 2 qᵀ w``, the position gap ``g0 + C w`` and the speed of the last
    planned sample ``dᵀ w`` (knots of the correction, or coordinates in a :class:`MovementSubspace`).
    One encoding constraint per network: the plan must satisfy every member (the ensemble's minimum).
    """
    cache_key = (key, m, method, time_limit, sharpness)
    if cache_key in _SOLVERS:
        return _SOLVERS[cache_key]
    members = len(networks)
    n_in = networks[0].hidden.in_features
    w = ca.MX.sym("w", m)  # in units of _U_SCALE
    s = ca.MX.sym("s")  # encoding slack, in logit units
    sizes = {"A": n_in * m, "x0": n_in, "H": m * m, "q": m, "C": 3 * m, "g0": 3, "d": m, "rhs": 4}
    p = ca.MX.sym("p", sum(sizes.values()))
    part = dict(zip(sizes, ca.vertsplit(p, [int(i) for i in np.cumsum([0, *sizes.values()])]), strict=True))
    a, h, c = ca.reshape(part["A"], n_in, m), ca.reshape(part["H"], m, m), ca.reshape(part["C"], 3, m)
    sign, z_rhs, speed_rhs, delta = ca.vertsplit(part["rhs"])
    cost = ca.dot(w, ca.mtimes(h, w)) + 2 * ca.dot(part["q"], w) + _PENALTY * s
    z = ensemble_logits(networks, sharpness)(ca.mtimes(a, w) + part["x0"])
    gap = part["g0"] + ca.mtimes(c, w)
    constraints = ca.vertcat(sign * z + s - z_rhs, ca.sumsqr(gap) - delta**2, ca.dot(part["d"], w) - speed_rhs)
    nlp = {"x": ca.vertcat(w, s), "p": p, "f": cost, "g": constraints}
    deadline = None
    if method == "ipopt":
        options = {
            "print_time": False,
            "ipopt.print_level": 0,
            "ipopt.sb": "yes",
            "ipopt.max_cpu_time": time_limit,
            "ipopt.tol": 1e-6,
            "ipopt.warm_start_init_point": "yes",
            "ipopt.mu_init": 1e-3,
        }
    else:
        rows = members + 2
        deadline = _Deadline({"x": m + 1, "f": 1, "g": rows, "lam_x": m + 1, "lam_g": rows, "lam_p": p.numel()})
        options = {
            "print_time": False,
            "print_header": False,
            "print_iteration": False,
            "print_status": False,
            "qpsol": "qrqp",
            # an indefinite QP can keep qrqp busy for tens of ms: cap it, the next SQP iteration recovers
            "qpsol_options": {
                "print_iter": False,
                "print_header": False,
                "print_info": False,
                "error_on_fail": False,
                "max_iter": 50,
            },
            "max_iter": 50,
            "error_on_fail": False,
            "iteration_callback": deadline,
        }
    solver = _Solver(ca.nlpsol(f"optimal_blending_{m}", method, nlp, options), deadline)
    _SOLVERS[cache_key] = solver
    return solver


def solve_decision(blender: Any, problem: dict[str, Any], w0: np.ndarray) -> tuple[np.ndarray | None, np.ndarray, str]:
    """Knots (None: fall back), multipliers and status of one casadi solve of ``blender``'s decision.

    ``blender`` is the :class:`~cogblocks.amplification.OptimalBlender` whose networks, settings and
    multipliers (the dual's warm start) the solve uses.
    ``problem`` is the decision's (:func:`~cogblocks.amplification.plan.plan_problem`), ``w0`` the warm start.
    """
    members, m = len(blender.networks), len(w0)
    solver = _solver(blender.networks, blender._key, m, blender.solver, blender.time_limit_ms / 1e3, blender.sharpness)
    slack = max(blender._z_target - blender._sign * blender._logit(problem["x0"] + problem["A"] @ w0), 0.0)
    if solver.deadline is not None:
        solver.deadline.start(blender.time_limit_ms / 1e3)
    out = solver.function(
        x0=np.r_[w0, slack],
        p=np.concatenate([np.ravel(problem[k], order="F") for k in ("A", "x0", "H", "q", "C", "g0", "d", "rhs")]),
        lbx=np.r_[np.full(m, -np.inf), 0.0],
        ubx=np.inf,
        lbg=np.r_[np.zeros(members), -np.inf, 0.0],
        ubg=np.r_[np.full(members, np.inf), 0.0, np.inf],
        lam_g0=blender.multipliers[: members + 2],
        lam_x0=np.r_[np.zeros(m), blender.multipliers[members + 2]],
    )
    x = np.asarray(out["x"]).ravel()
    multipliers = np.r_[np.asarray(out["lam_g"]).ravel(), np.asarray(out["lam_x"]).ravel()[-1]]
    w = x[:-1]
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(multipliers))):
        return None, multipliers, "fallback"
    if solver.function.stats()["success"]:
        return w, multipliers, "converged"
    z = blender._sign * blender._logit(problem["x0"] + problem["A"] @ w)
    if z > blender._z_clip and np.linalg.norm(problem["g0"] + problem["C"] @ w) <= blender.delta_pos:
        return w, multipliers, "accepted"
    return None, multipliers, "fallback"
