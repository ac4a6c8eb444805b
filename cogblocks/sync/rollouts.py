"""Fast rollouts of the whole-run search's model: the tick model over a plan, and the reference rules in NumPy.

A decision of :class:`~cogblocks.sync.receding.RecedingPlanMotion` spends most of its time rolling a model out to the
trial's end (:mod:`cogblocks.sync.whole_run`). The functions here compute exactly what the plain formulations do, bit
for bit, with less overhead:

* :func:`alteration_rollout` evaluates the mapped tick model through casadi's zero-copy buffers, writing every chunk
  straight into the result (no conversion of casadi matrices to NumPy arrays);
* :func:`rollout_function` compiles the mapped tick model to machine code when a C compiler is at hand (casadi's
  ``jit`` with the ``shell`` compiler, floating-point contraction off, so every operation rounds as casadi's own
  virtual machine rounds it), and falls back to the virtual machine otherwise: the same numbers, only slower;
* :func:`rule_rollouts` runs the reference rules' closed loops with the blender's law
  (:func:`~cogblocks.sync.blending.alteration`, :func:`~cogblocks.sync.blending.lam_step`) unrolled for NumPy
  arrays: the same ufuncs in the same order, without the law's per-call type dispatch.
"""

from __future__ import annotations

import tempfile

import casadi as ca
import numpy as np

from cogblocks.data.groups import SyncGroup
from cogblocks.sync.blending import BlenderParams
from cogblocks.sync.model import DT

__all__ = [
    "CHUNK",
    "JIT_FLAGS",
    "alteration_rollout",
    "compiled_rollout",
    "memory",
    "rollout_function",
    "rule_rollouts",
    "stepped",
]

CHUNK = 1000  # ticks per casadi rollout call

#: Flags of the C compiler :func:`compiled_rollout` calls: no fused multiply-add, so the compiled code rounds every
#: operation as casadi's virtual machine does.
JIT_FLAGS = ("-O2", "-ffp-contract=off")

_TWO_PI = 2.0 * np.pi


def memory(params: BlenderParams) -> int:
    """Entries the model's state carries for the blender's memory: the last alteration (1) with a slew limit, else 0.

    The state of :func:`~cogblocks.sync.whole_run.tick_model` is ``(θ, λ)`` followed by them, that of
    :func:`~cogblocks.sync.whole_run.identified_tick_model` ``(θ, λ, ω, K)`` followed by them."""
    return 0 if params.slew is None else 1


def compiled_rollout(tick: ca.Function, chunk: int = CHUNK) -> ca.Function:
    """``tick.mapaccum("roll", chunk)`` compiled to machine code, or evaluated by casadi if no compiler works.

    The compiled function gives the same numbers as the interpreted one (a test checks it bit for bit); it is about
    three times faster and costs a second or two of compiler time, once per tick model.
    """
    with tempfile.TemporaryDirectory(prefix="cogblocks-jit-", ignore_cleanup_errors=True) as directory:
        options = {
            "jit": True,
            "jit_cleanup": False,  # the directory goes: a loaded library needs no file
            "compiler": "shell",
            "jit_options": {"flags": list(JIT_FLAGS), "directory": directory, "cleanup": False, "verbose": False},
        }
        try:
            return tick.mapaccum("roll", chunk, options)
        except RuntimeError:  # no C compiler (or one that refuses the flags): casadi's virtual machine
            return tick.mapaccum("roll", chunk)


def rollout_function(tick: ca.Function, solvers: dict | None = None) -> ca.Function:
    """``tick`` mapped over :data:`CHUNK` ticks, as :func:`alteration_rollout` takes it.

    With ``solvers`` (a cache kept by the caller for one ``tick``) it is compiled once (:func:`compiled_rollout`)
    and cached there; without, it is built afresh and interpreted.
    """
    if solvers is None:
        return tick.mapaccum("roll", CHUNK)
    if "roll" not in solvers:
        solvers["roll"] = compiled_rollout(tick)
    return solvers["roll"]


def alteration_rollout(roll: ca.Function, x0: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """States before each tick (``len(s)`` × the state's size) and r of each tick, for the alteration fractions ``s``.

    ``roll`` is :func:`~cogblocks.sync.whole_run.tick_model` mapped over a chunk of ticks
    (``tick.mapaccum("roll", CHUNK)``); ``x0`` the state before the first tick; the last chunk is padded with zeros
    (a tick depends only on those before it, so the padding changes nothing that is returned).
    """
    chunk, size = roll.size2_in(1), roll.size1_in(0)
    n_ticks = len(s)
    chunks = -(-n_ticks // chunk)
    # row j + 1 is the state after tick j: a chunk's (chunk × size) rows are casadi's (size × chunk) columns
    states = np.empty((chunks * chunk + 1, size))
    r = np.empty(chunks * chunk)
    fractions = np.zeros(chunks * chunk)
    fractions[:n_ticks] = s
    states[0] = np.asarray(x0, dtype=float).ravel()
    buffer, evaluate = roll.buffer()
    for c in range(chunks):
        a = c * chunk
        buffer.set_arg(0, memoryview(states[a]))
        buffer.set_arg(1, memoryview(fractions[a : a + chunk]))
        buffer.set_res(0, memoryview(states[a + 1 : a + 1 + chunk]))
        buffer.set_res(1, memoryview(r[a : a + chunk]))
        evaluate()
    return states[:n_ticks], r[:n_ticks]


def stepped(tick: ca.Function, x0: np.ndarray, alterations: np.ndarray, n: int) -> np.ndarray:
    """The state after one ``tick`` per entry of ``alterations`` (rad) from ``x0``: each tick asks for its
    alteration as the fraction of that tick's λ (``x[n]``), clipped to [−1, 1]."""
    x = np.array(x0, dtype=float).ravel()
    after, r, fraction = np.empty_like(x), np.empty(1), np.empty(1)
    buffer, evaluate = tick.buffer()
    buffer.set_arg(0, memoryview(x))
    buffer.set_arg(1, memoryview(fraction))
    buffer.set_res(0, memoryview(after))
    buffer.set_res(1, memoryview(r))
    for a in alterations:
        fraction[0] = min(max(a / x[n], -1.0), 1.0)
        evaluate()
        x[...] = after
    return x


def rule_rollouts(
    group: SyncGroup,
    adjacency: np.ndarray,
    params: BlenderParams,
    state: np.ndarray,
    rules: tuple[np.ndarray, np.ndarray, np.ndarray],
    n_ticks: int,
    record: bool,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Reference rules in closed loop from ``state`` (θ, λ), all at once on the exact NumPy model.

    ``rules = (kind, phase0, freq)``: kind 0 does nothing (θ_ref = θ_L0), 1 follows the circular mean of the
    others, 2 is the constant frequency θ_ref = phase0 + freq · t (t from ``state``). Returns the r of every tick
    and rule (``n_ticks`` × rules) if ``record``, else only their sums, and the alteration fractions if ``record``.
    """
    kind, phase0, freq = rules
    b, i, n = len(kind), group.assisted, group.n
    others = np.arange(n) != i
    omega = np.asarray(group.omega, dtype=float)
    gain = group.gain
    theta, lam = np.tile(state[:n], (b, 1)), np.full(b, state[n])
    shift = np.full(b, state[-1] if memory(params) else 0.0)
    total = np.zeros((n_ticks, b) if record else b)
    s = np.zeros((n_ticks, b)) if record else None
    # the blender's law (blending.alteration and blending.lam_step on arrays), its constants computed once
    mean, nothing = kind == 1, kind == 0
    continuous, hard, slew = params.continuous, params.saturation == "hard", params.slew
    step = None if slew is None else slew * DT
    lam_min, e_max, span = params.lam_min, params.e_max, params.lam_max - params.lam_min
    triangular, kappa_plus, kappa_minus = params.psi == "triangular", params.kappa_plus, params.kappa_minus
    for k in range(n_ticks):
        z = np.exp(1j * theta)
        others_sum = z[:, others].sum(axis=1)  # np.angle's arctan2, without its Python wrapper
        reference = np.where(mean, np.arctan2(others_sum.imag, others_sum.real), phase0 + freq * (k * DT))
        l0 = theta[:, i]
        d = np.where(nothing, 0.0, np.mod(reference - l0 + np.pi, _TWO_PI) - np.pi)
        if continuous:
            d = shift + (np.pi - np.mod(np.pi - (d - shift), _TWO_PI))
        low = -lam
        if hard:
            a = np.minimum(np.maximum(d, low), lam)
        else:
            a = d / (1.0 + abs(d / lam) ** 4.0) ** (1.0 / 4.0)
        if step is not None:
            a = np.minimum(np.maximum(np.minimum(np.maximum(a, shift - step), shift + step), low), lam)
        shift = a
        z[:, i] = np.exp(1j * (l0 + shift))
        r = np.abs(z.sum(axis=1)) / n
        if record:
            total[k], s[k] = r, shift / lam
        else:
            total += r
        ax = np.abs(shift / e_max)
        if triangular:
            psi = np.maximum(0.0, 1.0 - ax)
        else:
            with np.errstate(divide="ignore", over="ignore"):
                psi = np.where(ax < 1.0, np.exp(1.0 - 1.0 / (1.0 - np.minimum(ax, 1.0) ** 2)), 0.0)
        target = psi * span + lam_min
        lam = lam - DT * np.where(lam <= target, kappa_plus, kappa_minus) * (lam - target)
        theta = theta + DT * (omega + gain * (z.conj() * (z @ adjacency.T)).imag)
    return total, (np.clip(s, -1.0, 1.0) if record else None)
