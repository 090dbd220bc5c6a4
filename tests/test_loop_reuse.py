"""Work the residual loop reuses within one fit gives the numbers computing it afresh gives.

The loop filters the measured accelerations once per part, builds a damping block from one
evaluation of the basis library, simulates each model and mode once, solves a filter's
initial state once per sample rate and autocorrelates each input signal once for all DOFs.
Each reuse must be exact (the loop's outputs are pinned bit for bit), and must happen.
"""

from __future__ import annotations

from importlib import resources

import numpy as np
import pytest

import nnid.loop.residual_loop as residual_loop
import nnid.models.parametric as parametric
from nnid.loop.diagnose import Workspace, damping_block
from nnid.loop.effects import candidates
from nnid.loop.residual_loop import ResidualLoop
from nnid.loop.scenarios import effect_log
from nnid.loop.unexplained import unexplained_structure
from nnid.models.parametric import ParametricFossen, filter_signal
from nnid.vehicle import load_vehicle

MINIROV = str(resources.files("nnid.demo_data").joinpath("minirov.toml"))


@pytest.fixture(scope="module")
def small():
    """A short three-run log of 'minirov' (30 s), split by runs, and its workspace."""
    veh = load_vehicle(MINIROV)
    log = effect_log(veh, duration=30, dt=0.05, n_experiments=3, seed=0)
    train = log[log["experiment"] != log["experiment"].iloc[-1]]
    val = log[log["experiment"] == log["experiment"].iloc[-1]]
    return veh, log, Workspace(train, val, veh, 1.0)


def test_damping_block_is_the_damping_columns_stacked(small):
    veh, log, ws = small
    cands = [c for c in candidates(veh, log, True) if c.linear and ":" in c.parameter][:12]
    data = ws.arrays(veh)
    structure = ParametricFossen(veh, [c.parameter for c in cands])
    names, xi, rows = structure.damping_terms(data, 1.0)
    cols = structure.damping_columns(data, 1.0)
    assert names == structure.names
    for k, name in enumerate(names):
        assert np.array_equal(cols[name][:, rows[k]], -xi[:, k])
    expected = np.stack([cols[n] for n in structure.names], 2)[ws.settled(data)]
    assert np.array_equal(damping_block(ws, veh, cands, data), expected)


def test_the_filtered_acceleration_given_is_the_one_computed(small):
    veh, _, ws = small
    data = ws.arrays(veh)
    nu_dot_f = ws.nu_dot_f("train")
    assert ws.nu_dot_f("train") is nu_dot_f  # filtered once
    assert np.array_equal(nu_dot_f, filter_signal(data, data["nu"], 1.0, derivative=True))
    assert Workspace(ws.train, ws.val, veh, None).nu_dot_f("train") is None
    structure = ParametricFossen(veh, ["Z_wdot", "r_g.z", "Z:w"])
    assert np.array_equal(
        structure.equation_residual(structure.base, data, 1.0, nu_dot_f),
        structure.equation_residual(structure.base, data, 1.0),
    )
    given, fresh = structure.regression(data, 1.0, nu_dot_f), structure.regression(data, 1.0)
    assert np.array_equal(given.phi, fresh.phi) and np.array_equal(given.y, fresh.y)


def test_a_filter_start_is_solved_once_per_sample_rate(small, monkeypatch):
    _, _, ws = small
    calls = []

    def counted(b, a):
        calls.append(1)
        return parametric_lfilter_zi(b, a)

    parametric_lfilter_zi = parametric.lfilter_zi
    data = ws.data
    reference = filter_signal(data, data["nu"], 1.0)
    monkeypatch.setattr(parametric, "lfilter_zi", counted)
    assert np.array_equal(filter_signal(data, data["nu"], 1.0), reference)
    assert len(np.unique(data["experiment"])) == 2 and len(calls) == 1


def test_a_held_out_simulation_is_run_once_per_model_and_mode(small, monkeypatch):
    veh, _, ws = small
    calls = []

    def simulated(vehicle, log, mode, warmup_s, dofs):
        calls.append((vehicle, mode))
        return {"u": 0.25, "total": 0.25}, {}

    monkeypatch.setattr(residual_loop, "velocity_scores", simulated)
    loop = ResidualLoop(veh)
    loop.dofs_ = ("u",)
    ws = Workspace(ws.train, ws.val, veh, 1.0)  # a fresh fit's memo
    first = loop._velocity_scores(ws, veh, "free_run")
    assert loop._simulation_error(ws, veh, "free_run") == 0.25
    second = loop._velocity_scores(ws, veh, "free_run")
    assert len(calls) == 1 and first == second and first[0] is not second[0]
    loop._velocity_scores(ws, veh, "one_step")
    loop._velocity_scores(ws, veh.model_copy(), "free_run")  # another model: simulated
    assert len(calls) == 3


def test_shared_autocorrelations_give_each_dofs_structure(rng):
    """Each DOF's correlates are the same whether the signals' autocorrelations are shared
    (a memo) or computed for it alone, also for a DOF with other finite samples."""
    n, dt = 3000, 0.05
    t = np.arange(n) * dt
    experiment = np.repeat([0, 1], n // 2)
    inputs = {"tau_X": np.sin(0.7 * t) + 0.1 * rng.normal(size=n), "tau_Z": rng.normal(size=n)}
    velocities = {"u": np.cos(0.3 * t), "w": 0.2 * rng.normal(size=n)}
    residuals = [
        0.8 * np.roll(inputs["tau_X"], 20) + 0.3 * rng.normal(size=n),
        0.5 * inputs["tau_X"] * velocities["u"] + 0.3 * rng.normal(size=n),
        0.6 * np.roll(inputs["tau_Z"], 40) + 0.3 * rng.normal(size=n),
    ]
    residuals[2][100:110] = np.nan  # other samples: its own signal segments
    memo: dict = {}
    for residual in residuals:
        alone = unexplained_structure(residual, inputs, velocities, experiment, dt, 9)
        shared = unexplained_structure(residual, inputs, velocities, experiment, dt, 9, memo=memo)
        assert alone and shared == alone
    signals = len(inputs) * (1 + len(velocities))
    assert len(memo) == 2 * signals  # two sets of finite samples, each signal once per set
