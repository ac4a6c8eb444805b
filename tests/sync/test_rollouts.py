"""The whole-run search's fast rollouts give the numbers of their plain formulations bit for bit, and so the
receding planner's decisions are those it made through the plain ones."""

from __future__ import annotations

import dataclasses
import shutil
import tempfile

import casadi as ca
import numpy as np
import pytest

import cogblocks.sync.receding as receding
import cogblocks.sync.whole_run as whole_run
from cogblocks.data.groups import TABLE2, random_groups
from cogblocks.diagrams.sync import MOTIONS, pop_sync
from cogblocks.sim import Simulator
from cogblocks.sync.blending import CONTINUOUS, DELIVERABLE, BlenderParams, alteration, lam_step
from cogblocks.sync.coupling import Coupling
from cogblocks.sync.model import DT
from cogblocks.sync.rollouts import (
    CHUNK,
    JIT_FLAGS,
    alteration_rollout,
    compiled_rollout,
    memory,
    rule_rollouts,
    stepped,
)
from cogblocks.sync.whole_run import identified_tick_model, state_rules, switch_rules

SMOOTH = BlenderParams(saturation="smooth", psi="bump", continuous=True)
BLENDERS = {"deliverable": DELIVERABLE, "continuous": CONTINUOUS, "smooth": SMOOTH}


def _plain_rollout(roll: ca.Function, x0: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rollout through casadi matrices, chunk by chunk (how the search first wrote it)."""
    states, rs = [], []
    x = ca.DM(x0)
    for start in range(0, len(s), CHUNK):
        part = s[start : start + CHUNK]
        xs, r = roll(x, np.pad(part, (0, CHUNK - len(part)))[None, :])
        xs, r = np.asarray(xs), np.asarray(r).ravel()
        before = np.column_stack([np.asarray(x), xs[:, :-1]])
        states.append(before[:, : len(part)].T)
        rs.append(r[: len(part)])
        x = ca.DM(before[:, len(part)]) if len(part) < CHUNK else ca.DM(xs[:, -1])
    return np.concatenate(states), np.concatenate(rs)


def _plain_rules(group, adjacency, params, state, rules, n_ticks, record):
    """The rule rollouts through the blender's own law (blending.alteration and lam_step, type dispatch and all)."""
    kind, phase0, freq = rules
    b, i, n = len(kind), group.assisted, group.n
    others = np.arange(n) != i
    omega = np.asarray(group.omega, dtype=float)
    theta, lam = np.tile(state[:n], (b, 1)), np.full(b, state[n])
    shift = np.full(b, state[-1] if memory(params) else 0.0)
    total = np.zeros((n_ticks, b) if record else b)
    s = np.zeros((n_ticks, b)) if record else None
    for k in range(n_ticks):
        z = np.exp(1j * theta)
        reference = np.where(kind == 1, np.angle(z[:, others].sum(axis=1)), phase0 + freq * (k * DT))
        l0 = theta[:, i]
        d = np.where(kind == 0, 0.0, np.mod(reference - l0 + np.pi, 2 * np.pi) - np.pi)
        shift = alteration(d, lam, params, shift, DT)
        z[:, i] = np.exp(1j * (l0 + shift))
        r = np.abs(z.sum(axis=1)) / n
        if record:
            total[k], s[k] = r, shift / lam
        else:
            total += r
        lam = lam_step(lam, shift, params, DT)
        theta = theta + DT * (omega + group.gain * (z.conj() * (z @ adjacency.T)).imag)
    return total, (np.clip(s, -1.0, 1.0) if record else None)


def _plain_stepped(tick: ca.Function, x: np.ndarray, alterations: np.ndarray, n: int) -> np.ndarray:
    for a in alterations:
        x = np.asarray(tick(x, min(max(float(a) / x[n], -1.0), 1.0))[0], dtype=float).ravel()
    return x


def _model(group, params):
    adjacency = Coupling(group.graph, group.n).matrix
    tick = identified_tick_model(group.n, group.assisted, adjacency, params)
    rng = np.random.default_rng(group.n)
    theta = rng.uniform(0.0, 2 * np.pi, group.n)
    x = np.r_[theta, 1.1, group.omega, group.gain, [0.2] * memory(params)]
    return adjacency, tick, x, rng


@pytest.mark.parametrize("name", sorted(BLENDERS))
def test_the_buffered_rollout_is_the_plain_one_bit_for_bit(name):
    group = TABLE2[1]
    _, tick, x, rng = _model(group, BLENDERS[name])
    roll = tick.mapaccum("roll", CHUNK)
    s = np.clip(rng.normal(0.0, 0.6, 2 * CHUNK + 317), -1.0, 1.0)  # two full chunks and a padded one
    states, r = alteration_rollout(roll, x, s)
    plain_states, plain_r = _plain_rollout(roll, x, s)
    assert states.shape == (len(s), tick.size1_in(0)) and r.shape == (len(s),)
    np.testing.assert_array_equal(states, plain_states)
    np.testing.assert_array_equal(r, plain_r)
    # and tick by tick: the state each tick starts from, then what the tick model makes of it
    assert np.array_equal(states[0], x)
    for j in (0, CHUNK - 1, CHUNK, len(s) - 2):
        after, r_j = tick(states[j], s[j])
        assert np.array_equal(np.asarray(after).ravel(), states[j + 1]) and float(r_j) == r[j]


@pytest.mark.skipif(shutil.which("gcc") is None and shutil.which("cc") is None, reason="no C compiler to compile with")
@pytest.mark.parametrize("name", ["continuous", "smooth"])
def test_the_compiled_rollout_rounds_as_casadis_virtual_machine(name):
    group = random_groups(12, "validation", 0)[11]  # N = 15, all-to-all
    _, tick, x, rng = _model(group, BLENDERS[name])
    s = np.clip(rng.normal(0.0, 0.6, CHUNK + 10), -1.0, 1.0)
    want = alteration_rollout(tick.mapaccum("roll", CHUNK), x, s)
    with tempfile.TemporaryDirectory() as directory:  # compiled as compiled_rollout does, but failing loudly
        options = {"jit": True, "jit_cleanup": False, "compiler": "shell"}
        options["jit_options"] = {"flags": list(JIT_FLAGS), "directory": directory, "cleanup": False}
        compiled = tick.mapaccum("roll", CHUNK, options)
    for roll in (compiled, compiled_rollout(tick)):
        for got, plain in zip(alteration_rollout(roll, x, s), want, strict=True):
            np.testing.assert_array_equal(got, plain)


@pytest.mark.parametrize("name", sorted(BLENDERS))
def test_the_rule_rollouts_are_the_blenders_law_bit_for_bit(name):
    params = BLENDERS[name]
    group = TABLE2[3]
    adjacency, _, x, _ = _model(group, params)
    state = np.r_[x[: group.n + 1], x[2 * group.n + 2 :]]
    rules = state_rules(group, state)
    for record in (False, True):
        got = rule_rollouts(group, adjacency, params, state, rules, 300, record)
        want = _plain_rules(group, adjacency, params, state, rules, 300, record)
        np.testing.assert_array_equal(got[0], want[0])
        if record:
            np.testing.assert_array_equal(got[1], want[1])
    # the rules a window switches to, from a state with the blender's memory
    r_rules, s_rules = switch_rules(group, adjacency, params, state, 0.3, 200)
    assert r_rules.shape == s_rules.shape == (200, 34) and np.all((0.0 <= r_rules) & (r_rules <= 1.0 + 1e-12))


def test_stepping_through_alterations_is_tick_by_tick_casadi():
    group = TABLE2[1]
    _, tick, x, rng = _model(group, CONTINUOUS)
    alterations = rng.normal(0.0, 1.5, 150)  # some beyond ±λ: clipped to the fraction ±1
    np.testing.assert_array_equal(stepped(tick, x, alterations, group.n), _plain_stepped(tick, x, alterations, group.n))
    np.testing.assert_array_equal(stepped(tick, x, np.zeros(0), group.n), x)


def _decisions(group):
    block = MOTIONS["replan"](group)
    trace = Simulator(pop_sync(group, motion=block)).run(n_steps=round(group.duration / DT) + 1)
    return block.plans, np.asarray(trace["r"])


@pytest.mark.parametrize("index", [2, 4, 7])
def test_the_default_planner_decides_as_through_the_plain_rollouts(index, monkeypatch):
    group = dataclasses.replace(random_groups(8, "validation", 0)[index], duration=8.0)
    fast_plans, fast_r = _decisions(group)
    # every rewritten function back to its plain formulation, the rollout interpreted by casadi's virtual machine
    for module in (receding, whole_run):
        monkeypatch.setattr(module, "alteration_rollout", _plain_rollout)
        monkeypatch.setattr(module, "rule_rollouts", _plain_rules)
    monkeypatch.setattr(receding, "stepped", _plain_stepped)
    interpreted = lambda tick, chunk=CHUNK: tick.mapaccum("roll", chunk)  # noqa: E731
    monkeypatch.setattr("cogblocks.sync.rollouts.compiled_rollout", interpreted)
    plain_plans, plain_r = _decisions(group)
    assert len(fast_plans) == len(plain_plans) >= 5
    for (start, a, r), (plain_start, plain_a, plain_r_pred) in zip(fast_plans, plain_plans, strict=True):
        assert start == plain_start
        np.testing.assert_array_equal(a, plain_a)
        np.testing.assert_array_equal(r, plain_r_pred)
    np.testing.assert_array_equal(fast_r, plain_r)
