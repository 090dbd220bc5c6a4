"""Caccia's two-step procedure (nnid.trainers.caccia): a Table II analogue on a simulated ROMEO
heave campaign, the η = 1 bias of Fig. 6, the d-optimal inertia step and the 51.02 % rule."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from nnid import load_model
from nnid.config import SimulateConfig, TrainConfig, load_config
from nnid.datasets.arrays import log_arrays
from nnid.datasets.simulator import simulate_config
from nnid.models.caccia import CacciaModel
from nnid.models.parametric import ParametricFossen
from nnid.physics.effects import apply_effect
from nnid.physics.thrusters import Actuation
from nnid.trainers.caccia import (
    CacciaTwoStep,
    Plateau,
    force_to_commands,
    simulate_sinusoid,
    steady_state_regression,
)
from nnid.trainers.least_squares import INSIGNIFICANT_PERCENT
from nnid.vehicle import load_vehicle

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "romeo_heave_caccia.toml"
# Noise seed of the campaign. "All five within 2σ" is a joint statement about five correlated
# estimates: for a calibrated σ̂ it holds in roughly 80 % of noise draws. Over campaign seeds
# 0, 100, …, 1000 it held for 9 of 11 and 51 of the 55 pairs (seed 0: η_w at 3.2σ, k_w 2.7σ, W
# 2.2σ; seed 100: ΔW at 2.2σ); with the plateaus' former, too small speed s.e. also 9 of 11
# (seed 0: η_w 2.1σ, seed 600: ΔW 2.1σ), when σ(m_w) and the 51.02 % flag held for all 11.
# A fixed seed keeps the test deterministic.
CAMPAIGN_SEED = 700


@pytest.fixture(scope="module")
def setup():
    cfg = load_config(CONFIG, TrainConfig)
    campaign = load_config(CONFIG.parent / cfg.data.campaign, SimulateConfig)
    campaign = campaign.model_copy(update={"seed": CAMPAIGN_SEED})
    vehicle = load_vehicle(cfg.vehicle)
    log = simulate_config(campaign, vehicle)
    return cfg, campaign, vehicle, log


@pytest.fixture(scope="module")
def fitted(setup):
    cfg, campaign, vehicle, log = setup
    trainer = cfg.model.build(vehicle).trainer()
    trainer.fit_steady(log, vehicle)
    spec = cfg.data.sinusoid
    prior = trainer.rigid_inertia(vehicle) * (1 + spec.prior_added_fraction)
    design = trainer.design_sinusoid(spec.offset, spec.amplitude, prior, spec.duration)
    sine = simulate_sinusoid(
        vehicle, design, "w", campaign.dt, campaign.substeps, campaign.measurement, spec.seed
    )
    est = trainer.fit_logs(log, vehicle, sine)
    return trainer, est, design, sine


def truth(campaign, vehicle) -> dict[str, float]:
    """Caccia-signed truths: drag and η_w from the preset, W of experiment 0 and ΔW from the
    campaign's buoyancy offsets (W_i − B_i grows by the offset)."""
    offsets = [
        sum(e.value for e in exp.effects if e.name == "buoyancy_offset")
        for exp in campaign.experiments
    ]
    steps = np.diff(offsets)
    assert np.allclose(steps, 7.1)  # one diver's lead per experiment (Caccia L248)
    coef = vehicle.damping.coefficients
    return {
        "k_w": -coef["Z:w"],
        "k_w|w|": -coef["Z:w*abs(w)"],
        "W": vehicle.weight - vehicle.buoyancy + offsets[0],
        "delta_W": float(steps[0]),
        "eta.w.neg": vehicle.installation["w.neg"],
    }


def test_table2_analogue(setup, fitted):
    """[k_w, k_w|w|, W, ΔW, η_w] (eq. 20) within two reported σ of the truth."""
    _, campaign, vehicle, _ = setup
    trainer, *_ = fitted
    est = trainer.steady_
    true = truth(campaign, vehicle)
    assert est.names == list(true)
    assert len(trainer.plateaus_) == 30  # 5 weights × 3 levels × up and down, all settled
    for name, value, sigma in zip(est.names, est.theta, est.stderr, strict=True):
        assert abs(value - true[name]) <= 2 * sigma, (name, value, sigma, true[name])
    assert est.significant.all()
    assert true["W"] == pytest.approx(-13.5)  # Table II


def test_vehicle_names_and_signs(setup, fitted):
    """Fossen names and signs: "Z:w" = −k_w, "weight_minus_buoyancy" = W, Z_wdot = −(m_w − m)."""
    _, _, vehicle, _ = setup
    trainer, est, *_ = fitted
    assert est.names == [
        "Z:w",
        "Z:w*abs(w)",
        "weight_minus_buoyancy",
        "delta_weight",
        "eta.w.neg",
        "Z_wdot",
    ]
    caccia = trainer.steady_
    np.testing.assert_allclose(est.theta[:2], -caccia.theta[:2])
    np.testing.assert_allclose(est.theta[2:5], caccia.theta[2:5])
    np.testing.assert_allclose(est.stderr[:5], caccia.stderr)
    assert est.theta[5] == pytest.approx(-(trainer.inertia_.theta[0] - vehicle.mass))
    assert est.as_dict()["Z:w"]["value"] < 0  # drag


def test_forced_eta_overestimates_weight(setup, fitted):
    """Caccia Fig. 6: with η_w = 1 for upward thrust the overestimated upward force is
    compensated by a weight that is always overestimated (W more positive = heavier), and
    the fit is far worse."""
    _, campaign, vehicle, log = setup
    trainer, *_ = fitted
    forced = CacciaTwoStep(force_eta_one=True)
    est = forced.fit_steady(log, vehicle)
    assert "eta.w.neg" not in est.names
    w_true = truth(campaign, vehicle)["W"]
    w_forced = est.theta[est.names.index("W")]
    assert w_forced - w_true > 3 * est.stderr[est.names.index("W")]
    assert w_forced > trainer.steady_.theta[2]
    dw_forced = est.theta[est.names.index("delta_W")]
    true = truth(campaign, vehicle)
    for i in range(5):  # every weight setting comes out heavier than it was
        assert w_forced + i * dw_forced > true["W"] + i * true["delta_W"]
    rms_forced = np.sqrt(np.mean(forced.residuals() ** 2))  # N, eq.-7 rows
    rms_free = np.sqrt(np.mean(trainer.residuals() ** 2))
    assert rms_forced > 10 * rms_free


def test_inertia_from_doptimal_sinusoid(setup, fitted):
    """Eqs 13-19: the sinusoid is designed from the step-1 drag and m_w = m − Z_wdot comes back
    within 2σ and 10 %."""
    _, _, vehicle, _ = setup
    trainer, est, design, sine = fitted
    k1, k2 = trainer.steady_.theta[:2]
    k_l = k1 + 2 * k2 * (-k1 + np.sqrt(k1**2 + 4 * k2 * design.offset)) / (2 * k2)
    assert design.frequency() == pytest.approx(k_l / (np.sqrt(3) * 675.0))  # eq. 14, prior
    tau = Actuation(vehicle).nominal(sine[[c for c in sine if c.startswith("cmd_")]].to_numpy())
    assert tau[:, 2].min() > 0  # no propeller inversion (L141)
    m_true = vehicle.mass - vehicle.added_mass["Z_wdot"]
    m, s = trainer.inertia_.theta[0], trainer.inertia_.stderr[0]
    assert abs(m - m_true) <= 2 * s
    assert abs(m - m_true) <= 0.1 * m_true
    z_wdot, s_z = est.theta[-1], est.stderr[-1]
    assert abs(z_wdot - vehicle.added_mass["Z_wdot"]) <= 2 * s_z


def test_percentile_rule_flags_irrelevant_linear_term(setup):
    """51.02 % rule (L279): on purely quadratic heave drag the linear term is insignificant,
    the quadratic one is not."""
    _, campaign, vehicle, _ = setup
    quadratic = apply_effect(vehicle, "linear_damping.w", -vehicle.damping.coefficients["Z:w"])
    assert quadratic.damping.coefficients["Z:w"] == 0.0
    log = simulate_config(campaign, quadratic)
    est = CacciaTwoStep().fit_steady(log, quadratic)
    pe = dict(zip(est.names, est.percentile_error, strict=True))
    assert pe["k_w"] > INSIGNIFICANT_PERCENT
    assert not est.significant[est.names.index("k_w")]
    assert pe["k_w|w|"] < INSIGNIFICANT_PERCENT
    assert abs(est.theta[1] - 430.3) <= 2 * est.stderr[1]


def test_regression_rows_eq9_eq20():
    """H and y of eqs 8-10/20 on exact plateaus recover θ exactly; a second mode gets its own η."""
    k1, k2, w0, dw, eta = 44.7, 430.3, -13.5, 7.1, 0.56
    plateaus = []
    for i in range(3):
        for v in (0.1, 0.3, -0.1, -0.25):
            drive = k1 * v + k2 * v * abs(v) - w0 - i * dw
            force = drive if drive >= 0 else drive / eta
            plateaus.append(Plateau("e", i, "", force, v, 0.0, 0.0, 1.0, 10))
    h, y, names = steady_state_regression(plateaus)
    assert names == ["k_w", "k_w|w|", "W", "delta_W", "eta.w.neg"]
    theta, *_ = np.linalg.lstsq(h, y, rcond=None)
    np.testing.assert_allclose(theta, [k1, k2, w0, dw, eta], rtol=1e-9)
    row = h[3]  # v = −0.25, i = 0, upward thrust: [w, w|w|, −1, −i, −φⁿ] and y = 0
    assert plateaus[3].force < 0 and y[3] == 0
    assert row[2] == -1 and row[3] == 0 and row[4] == -plateaus[3].force
    other = [Plateau("e", 0, "front", 5.0, 0.01, 0.0, 0.0, 1.0, 10)]
    _, _, names2 = steady_state_regression(plateaus + other)
    assert names2[-1] == "eta.w.front.pos"


def test_fit_protocol_matches_fit_logs(setup, fitted):
    """``fit(structure, data)`` with log_arrays gives the same estimate as ``fit_logs``."""
    _, _, vehicle, log = setup
    _, est, _, sine = fitted
    structure = ParametricFossen(vehicle, ["Z:w", "Z:w*abs(w)"], dofs=["w"])
    data = {"steady": log_arrays(log, vehicle), "sinusoid": log_arrays(sine, vehicle)}
    again = CacciaTwoStep().fit(structure, data)
    assert again.names == est.names
    np.testing.assert_allclose(again.theta, est.theta, rtol=1e-10)


def test_force_to_commands_round_trip(setup):
    _, _, vehicle, _ = setup
    force = np.array([-80.0, -10.0, 0.0, 25.0, 140.0])
    tau = Actuation(vehicle).nominal(force_to_commands(vehicle, "w", force))
    np.testing.assert_allclose(tau[:, 2], force, atol=1e-3)
    np.testing.assert_allclose(np.delete(tau, 2, axis=1), 0.0, atol=1e-9)


def test_caccia_model_fits_one_log_and_keeps_weight_minus_buoyancy(setup, fitted, tmp_path):
    """The model protocol on the campaign and the sinusoid as one log: the same estimate as the
    procedure, predictions of the identified one-DOF plant, and W − B through a save and load
    (its buoyancy offset is part of the plant)."""
    _, _, vehicle, log = setup
    _, est, _, sine = fitted
    model = CacciaModel(vehicle).fit(pd.concat([log, sine], ignore_index=True))
    assert model.estimate_.names == est.names
    np.testing.assert_allclose(model.estimate_.theta, est.theta, rtol=1e-10)
    wb = model.params["weight_minus_buoyancy"]["value"]
    assert model.parts_.weight - model.parts_.buoyancy == pytest.approx(wb)
    model.save(tmp_path)
    back = load_model(tmp_path)
    assert back.params == model.params
    pd.testing.assert_frame_equal(back.predict(sine), model.predict(sine))
    assert list(model.residual(sine).columns) == ["Z"]
    assert model.describe()["inertia"] == "identified"


def test_its_scores_name_velocity_window_the_key_that_sets_their_window(setup, fitted):
    """The residual derives ẇ with the step-2 filter (velocity_window), yet scoring a 3-s run
    against its 5-s window was refused as "field 'savgol_window'", a key a Caccia config has
    not, and a window widened at the log's rate was said as savgol_window too."""
    from nnid.errors import NnidInputError
    from nnid.pipeline import score

    cfg, _, vehicle, log = setup
    _, _, _, sine = fitted
    model = CacciaModel(vehicle).fit(pd.concat([log, sine], ignore_index=True))
    dt = float(np.median(np.diff(sine["t"])))
    short = sine[sine["t"] < sine["t"].iloc[0] + 3.0].assign(experiment="short")
    assert len(short) * dt < model.velocity_window
    with pytest.raises(NnidInputError) as err:
        score(model, short, cfg, None, at=("model", cfg.model))
    assert err.value.field == "model.velocity_window", str(err.value)
    assert err.value.message.endswith("give a shorter velocity_window or a longer run")
    narrow = 2 * dt  # two samples: too few for velocity_order 4, widened
    with pytest.warns(UserWarning, match=rf"^velocity_window = {narrow:g} s is 2 samples"):
        model.set_params(velocity_window=narrow).residual(sine)


def test_a_missing_sinusoid_run_is_said_not_skipped_in_silence(setup, fitted):
    """The sinusoid run named otherwise ("sine"): step 2 did not run, the model flew the
    vehicle file's Z_wdot, and the report gave its validation score with no word of it."""
    _, _, vehicle, log = setup
    _, _, _, sine = fitted
    both = pd.concat([log, sine], ignore_index=True)
    with pytest.warns(UserWarning, match="no training run is the sinusoid experiment 'sine'"):
        model = CacciaModel(vehicle, sinusoid_experiment="sine").fit(both)
    assert "Z_wdot" not in model.params and model.describe()["inertia"] == "vehicle file"


def test_a_plateau_of_a_few_samples_is_not_used():
    """A 1-Hz log with min_plateau = 3 s: settled runs of 6 samples became plateaus, whose
    steady-speed s.e. from the four-parameter asymptote fit is not measured (with 3 samples it
    was ~0; 18 % of 4-sample speeds lay beyond 2 s.e.) and whose row weight 1/σ² then swamped
    step 1. Only the 30-sample plateau counts."""
    from nnid.trainers.caccia import find_plateaus

    rng = np.random.default_rng(0)
    force = np.r_[np.full(6, 1.0), np.full(30, 2.0), np.full(6, 3.0)]
    t = np.arange(force.size, dtype=float)
    position = np.r_[0.0, np.cumsum(0.1 * force[:-1])] + rng.normal(0, 1e-4, force.size)
    plateaus = find_plateaus(
        t, position, force, np.zeros(force.size, int), settle_window=5.0, min_plateau=3.0
    )
    assert [p.force for p in plateaus] == [2.0]
    assert all(p.n >= 10 for p in plateaus)  # MIN_PLATEAU_SAMPLES
    assert plateaus[0].speed == pytest.approx(0.2, abs=3 * plateaus[0].speed_std + 1e-6)
    # its s.e. bounded by hand: a straight line fitted to the plateau's 30 samples of 1e-4 m
    # noise has slope s.e. σ/√Σ(t − t̄)², and the asymptote fit may not be worse by 2x
    tt = t[(t >= plateaus[0].start) & (t <= plateaus[0].end)]
    assert plateaus[0].speed_std < 2 * 1e-4 / np.sqrt(np.sum((tt - tt.mean()) ** 2))


def test_a_plateau_lasts_min_plateau_from_its_first_sample_to_its_last():
    """min_plateau = 10 s at 1 Hz: a settled run of 10 samples lasts 9 s (its end − start), yet
    counted as (r1 − r0) dt = 10 s it was used; one of 11 samples lasts 10 s and counts, as
    does a 10-s run at 10 Hz (101 samples) whose median interval rounds below 0.1 s."""
    from nnid.trainers.caccia import find_plateaus

    rng = np.random.default_rng(0)
    force = np.r_[np.full(6, 1.0), np.full(10, 2.0), np.full(11, 3.0), np.full(6, 1.0)]
    t = np.arange(force.size, dtype=float)
    position = np.r_[0.0, np.cumsum(0.1 * force[:-1])] + rng.normal(0, 1e-4, force.size)
    plateaus = find_plateaus(
        t, position, force, np.zeros(force.size, int), settle_window=5.0, min_plateau=10.0
    )
    assert [p.force for p in plateaus] == [3.0]
    assert all(p.end - p.start >= 10.0 for p in plateaus)
    force = np.r_[np.full(60, 1.0), np.full(101, 2.0), np.full(60, 1.0)]
    t = np.arange(force.size) * 0.1
    position = np.r_[0.0, np.cumsum(0.01 * force[:-1])] + rng.normal(0, 1e-4, force.size)
    plateaus = find_plateaus(t, position, force, np.zeros(force.size, int), settle_window=2.0)
    assert [(p.force, p.n) for p in plateaus] == [(2.0, 101)]


def test_a_label_that_comes_back_is_two_runs_not_one_plateau():
    """Experiment 0's rows resume after experiment 1's (its clock running on), at the same
    input and another depth: the input held across the join made one segment, whose settled
    run stopped at the depth jump (250 of 300 samples), and the second run's plateau was
    dropped without a word. Each run gives its plateaus as if the two were separate."""
    from nnid.trainers.caccia import find_plateaus

    rng = np.random.default_rng(0)

    def run(forces, x0):
        f = np.repeat(forces, 300)  # 30 s per level at 10 Hz
        x = x0 + np.r_[0.0, np.cumsum(0.005 * f[:-1])] + rng.normal(0, 1e-3, f.size)
        return f, x

    (fa, xa), (fb, xb), (fc, xc) = run([1.0, 2.0], 0.0), run([3.0, 1.5], 5.0), run([2.0, 1.0], 10)
    n = fa.size
    force, position = np.r_[fa, fb, fc], np.r_[xa, xb, xc]
    t = np.r_[np.arange(n), np.arange(n), n + np.arange(n)] * 0.1
    separate = np.repeat([0, 1, 2], n)
    merged = np.repeat([0, 1, 0], n)

    def found(codes):
        plateaus = find_plateaus(t, position, force, codes)
        return sorted((p.force, p.start, p.end, p.n, p.speed) for p in plateaus)

    assert len(found(separate)) == 6
    assert found(merged) == found(separate)
    assert {p.setting for p in find_plateaus(t, position, force, merged) if p.start >= 60} == {0}


def test_plateaus_are_cut_at_missing_samples_and_other_uneven_stamps_are_refused():
    """find_plateaus took the median interval for every one: across a 20-s hole in a 10-Hz log
    at one input the filter saw a jump in depth, so the first 30-s plateau was cut to 25 s and
    the second dropped without a word; a plateau logged at 1 Hz inside a 10-Hz experiment
    counted 30 s as 3 s and was dropped too. A hole now cuts the plateau (two, each whole);
    a rate that changes is refused, naming the experiment."""
    from nnid.errors import NnidInputError
    from nnid.trainers.caccia import find_plateaus

    rng = np.random.default_rng(0)
    t = np.r_[np.arange(300), 500 + np.arange(300)] * 0.1
    position = 0.02 * t + rng.normal(0, 1e-3, t.size)
    plateaus = find_plateaus(t, position, np.full(t.size, 2.0), np.zeros(t.size, int))
    assert [p.n for p in plateaus] == [300, 300]
    assert [x for p in plateaus for x in (p.start, p.end)] == pytest.approx([0, 29.9, 50, 79.9])
    assert all(p.speed == pytest.approx(0.02, abs=3 * p.speed_std) for p in plateaus)
    # the window bounded by hand: the crudest speed of a plateau, its two end samples'
    # difference over its 29.9 s, has s.e. σ√2/29.9 (σ = 1 mm); its s.e. is within 5x that
    assert all(p.speed_std < 5 * 1e-3 * np.sqrt(2) / (p.end - p.start) for p in plateaus)
    t = np.r_[np.arange(600) * 0.1, 60.0 + np.arange(30)]  # then 30 s at 1 Hz
    force = np.r_[np.full(600, 1.0), np.full(30, 2.0)]
    position = np.r_[0.0, np.cumsum(0.01 * force[:-1] * np.diff(t))]
    with pytest.raises(NnidInputError, match=r"t of experiment dive3 is not uniformly sampled"):
        find_plateaus(t, position, force, np.zeros(t.size, int), names=["dive3"])
    # dropouts with a lone sample between two (and two samples between three) are cut, not
    # refused as another rate: the plateaus either side stay whole
    t = np.r_[np.arange(300), 310, 320, 321, 330, 340 + np.arange(300)] * 0.1
    position = 0.02 * t + rng.normal(0, 1e-3, t.size)
    plateaus = find_plateaus(t, position, np.full(t.size, 2.0), np.zeros(t.size, int))
    assert [p.n for p in plateaus] == [300, 300]


def test_a_clock_stamped_in_whole_ms_gives_the_plateaus_of_its_float_clock():
    """120 Hz stamped in whole milliseconds steps 8, 8, 9 ms. The median, 8 ms, took every
    9-ms step for a missing sample and cut the log into pieces of three samples: no plateau
    at all, without a word. The step is now the one the rest of nnid reads (the mean of the
    one-sample steps), also for an experiment whose rows resume after another's on a clock
    4 ms off its first piece's line: each piece keeps to its own."""
    from nnid.trainers.caccia import find_plateaus

    rng = np.random.default_rng(0)
    n = 2 * 20 * 120  # two 20-s levels at 120 Hz

    def run(forces):
        f = np.repeat(forces, n // 2)
        return f, np.r_[0.0, np.cumsum(0.05 * f[:-1] / 120)] + rng.normal(0, 1e-4, f.size)

    (fa, xa), (fb, xb), (fc, xc) = run([1.0, 2.0]), run([3.0, -1.5]), run([2.0, 1.0])
    force, position = np.r_[fa, fb, fc], np.r_[xa, xb, xc]
    exact = np.r_[np.arange(2 * n), 2 * n + 0.48 + np.arange(n)] / 120
    whole_ms = np.round(exact * 1000) / 1000
    assert set(np.round(np.diff(whole_ms[:n]) * 1000)) == {8.0, 9.0}

    def found(t, codes):
        return sorted((p.force, p.n, p.start, p.end, p.speed) for p in find_plateaus(
            t, position, force, codes, settle_window=2.0))  # fmt: skip

    want = found(exact, np.repeat([0, 1, 2], n))
    assert len(want) == 6
    for codes in ([0, 1, 2], [0, 1, 0]):
        got = found(whole_ms, np.repeat(codes, n))
        assert [p[:2] for p in got] == [p[:2] for p in want]
        # the stamps are the exact times to half a millisecond, the speeds to their noise
        assert np.array(got)[:, 2:4] == pytest.approx(np.array(want)[:, 2:4], abs=5e-4)
        assert [p[4] for p in got] == pytest.approx([p[4] for p in want], rel=1e-5)


def _wrapped(angle: np.ndarray) -> np.ndarray:
    """An angle as readers keep it, in [−π, π)."""
    return (angle + np.pi) % (2 * np.pi) - np.pi


# a yaw turn of DOF r as the readers deliver it: 0.5 rad/s for 30 s at 20 Hz, ψ wrapped at ±π
# three times (k_r = 2, k_r|r| = 1: the steady force)
TURN_T = np.arange(600) / 20
TURN_PSI = 0.5 * TURN_T + 2.0
TURN_FORCE = np.full(TURN_T.size, 2.0 * 0.5 + 1.0 * 0.25)


def test_a_turn_wrapped_at_pi_is_one_whole_plateau():
    """ψ wrapped at ±π: each 2π step was a jump in the SG acceleration, and the plateau was cut
    to the longest stretch between two wraps (or none was found). The yaw angle is unwrapped
    per segment (a hole in the log cuts one) and the whole turn is the plateau at its speed."""
    from nnid.trainers.caccia import find_plateaus

    wrapped = _wrapped(TURN_PSI)
    assert np.sum(np.abs(np.diff(wrapped)) > np.pi) == 3
    codes = np.zeros(TURN_T.size, int)
    (p,) = find_plateaus(TURN_T, wrapped, TURN_FORCE, codes, angle=True)
    assert (p.start, p.end, p.n) == (0.0, 29.95, 600)
    assert p.speed == pytest.approx(0.5, abs=1e-9)
    # a hole of 2 s (samples missing) cuts the turn in two stretches, each unwrapped alone
    keep = (TURN_T < 12.0) | (TURN_T >= 14.0)
    got = find_plateaus(TURN_T[keep], wrapped[keep], TURN_FORCE[keep], codes[keep], angle=True)
    assert [(p.start, p.end) for p in got] == [(0.0, 11.95), (14.0, 29.95)]
    assert [p.speed for p in got] == pytest.approx([0.5, 0.5], abs=1e-9)


def test_the_yaw_dof_unwraps_its_angle_in_both_steps():
    """CacciaTwoStep(dof="r") on wrapped ψ: step 1 found the plateaus between wraps, and
    step 2 (eqs 16-19) took each 2π step for motion in ξ and in k χ, θ = [m, m ξ₀ + k χ₀, b]
    came out far from the exact [0, 0, 0] of a steady turn (y ≡ 0). Both steps read the
    unwrapped angle, exactly as if the log had been unwrapped."""
    from nnid.trainers.caccia import integrated_regression

    speeds = np.array([0.3, -0.6, 0.9, -0.2, 0.5])
    t = np.arange(speeds.size * 600) / 20
    xi = np.repeat(speeds, 600)
    psi = 1.0 + np.r_[0.0, np.cumsum(xi[:-1]) / 20]
    force = 2.0 * xi + 1.0 * xi * np.abs(xi)
    trainer = CacciaTwoStep(dof="r", reference=(("", "pos"), ("", "neg")), correlated=False)
    trainer.steady_arrays(t, _wrapped(psi), force, np.zeros(t.size, int))
    assert [(p.start, p.end) for p in trainer.plateaus_] == [
        (30.0 * i, 30.0 * i + 29.95) for i in range(speeds.size)
    ]
    assert [p.speed for p in trainer.plateaus_] == pytest.approx(speeds, abs=1e-9)
    assert trainer.steady_.theta[:2] == pytest.approx([2.0, 1.0], abs=1e-6)
    wrapped = _wrapped(TURN_PSI)
    want = integrated_regression(TURN_T, TURN_PSI, TURN_FORCE, 2.0, 1.0)
    got = integrated_regression(TURN_T, wrapped, TURN_FORCE, 2.0, 1.0, angle=True)
    assert got[0] == pytest.approx(want[0], abs=1e-9)
    assert got[1] == pytest.approx(want[1], abs=1e-9)
    with pytest.warns(UserWarning, match="collinear"):  # a steady turn: ξ is constant
        theta = trainer.inertia_arrays(TURN_T, wrapped, TURN_FORCE).theta
    assert theta == pytest.approx([0.0, 0.0, 0.0], abs=1e-6)


def test_a_sinusoid_run_stamped_in_whole_ms_is_integrated_at_its_step():
    """Step 2 on a 120-Hz sinusoid run stamped in whole ms was refused as "not uniformly
    sampled" (every 9-ms step more than 10 % over the median 8 ms). It is now read at its
    step: the velocity column is the float clock's, not 8/8.33 of it."""
    from nnid.trainers.caccia import integrated_regression

    exact = np.arange(20 * 120) / 120
    position = 0.3 * np.sin(0.5 * exact)
    force = np.cos(0.5 * exact)
    whole_ms = np.round(exact * 1000) / 1000
    want = integrated_regression(exact, position, force, 1.0, 1.0)[0][:, 0]
    got = integrated_regression(whole_ms, position, force, 1.0, 1.0)[0][:, 0]
    assert got == pytest.approx(want, rel=1e-4, abs=1e-6)


def test_the_pieces_a_gap_cut_a_run_into_keep_its_weight_setting(setup):
    """resample_log cuts a run at a 5-s hole into pieces 'weight1#0', 'weight1#1' (piece_of
    'weight1'). Caccia took each piece for an experiment: by default a weight setting each
    (every later run's i shifted by one, ΔW 5.56 for 7.11), and with settings keyed by the
    runs' names 'no weight setting for experiments ['weight1#0', …]'. The pieces are their
    run: the fit is that of the log with the hole and no pieces, either way, bit for bit.

    Of the same samples: the no-pieces log is the pieces relabelled as their run. The log
    before resampling differs from them by the grid's rounding (t by up to 6e-14 s, z by
    8e-14 m), and each plateau's speed is the asymptote of a fit whose time constant minimises
    a flat RSS profile, whose minimiser a rounding change of the data moves by far more than
    rounding (speeds 2e-9 apart, 1e-15 with the plain slope): against that log, the fits
    differed by 1.2e-9 with AVX-512 BLAS kernels and 4e-10 with AVX2 ones."""
    from nnid.datasets.log import PIECE_OF
    from nnid.datasets.preprocess import resample_log

    cfg, _, vehicle, log = setup
    hole = (log["experiment"] == "weight1") & log["t"].between(100.0, 105.0)
    pieces = resample_log(log[~hole].reset_index(drop=True), 10.0, gap=1.0)
    assert {"weight1#0", "weight1#1"} <= set(pieces["experiment"])
    holed = pieces.assign(experiment=pieces[PIECE_OF].fillna(pieces["experiment"]))
    holed = holed.drop(columns=PIECE_OF)
    assert list(pd.unique(holed["experiment"])) == [f"weight{k}" for k in range(5)]
    for settings in (None, {f"weight{k}": k for k in range(5)}):
        fits = []
        for data in (holed, pieces):
            trainer = cfg.model.build(vehicle).trainer()
            trainer.settings = settings
            fits.append(trainer.fit_steady(data, vehicle))
        assert fits[1].names == fits[0].names
        np.testing.assert_array_equal(fits[1].theta, fits[0].theta)


def test_a_sinusoid_run_cut_at_a_gap_is_refused_saying_so(setup, fitted):
    """resample_log cuts the sinusoid run at a 5-s hole into 'sinusoid#0' and 'sinusoid#1'.
    Step 2 was refused with "the sinusoid log must hold one experiment", which said neither
    the gap nor what to do; the model did not take the pieces for the sinusoid run at all: it
    warned "no training run is the sinusoid experiment" and gave them to step 1. Eqs 16-19
    integrate over one uninterrupted run, so the pieces are refused naming the gap."""
    from nnid.datasets.preprocess import resample_log
    from nnid.errors import NnidInputError

    _, _, vehicle, log = setup
    trainer, _, _, sine = fitted
    holed = sine[~sine["t"].between(30.0, 35.0)].reset_index(drop=True)
    pieces = resample_log(holed, 1.0 / float(np.median(np.diff(sine["t"]))), gap=1.0)
    assert set(pieces["experiment"]) == {"sinusoid#0", "sinusoid#1"}
    said = r"sinusoid run 'sinusoid' was cut at time gaps into 2 pieces .*holes at t = 29"
    with pytest.raises(NnidInputError, match=said) as err:
        trainer.fit_inertia(pieces, vehicle)
    assert "longest is 'sinusoid#1'" in str(err.value)
    with pytest.raises(NnidInputError, match=said):
        CacciaModel(vehicle).fit(pd.concat([log, pieces], ignore_index=True))


def test_the_steps_excitation_verdicts_reach_the_estimate_under_its_names():
    """to_vehicle_signs renamed the parameters but kept the excitation report under Caccia's
    names (k_w|w|): its verdict matched no parameter; and the union of the two steps dropped
    both steps' reports. A parameter the data did not excite (a zero column) or separate (m_w
    collinear with the offset) showed as merely "not significant"."""
    from types import SimpleNamespace

    from nnid.trainers.least_squares import ExcitationWarning, solve_least_squares

    a, b, c = np.random.default_rng(0).normal(size=(3, 200))
    trainer = CacciaTwoStep(dof="w")
    with pytest.warns(ExcitationWarning):
        trainer.steady_ = solve_least_squares(
            np.stack([a, 0 * a, b], 1), a + b, names=["k_w", "k_w|w|", "W"]
        )
        trainer.inertia_ = solve_least_squares(
            np.stack([c, a, c], 1), a + c, names=["m_w", "x0", "b"]
        )
    signed = trainer.to_vehicle_signs(trainer.steady_).as_dict()
    assert signed["Z:w*abs(w)"]["excited"] is False and "excited" not in signed["Z:w"]
    params = trainer._finish(SimpleNamespace(mass=100.0)).as_dict()
    assert params["Z:w*abs(w)"]["excited"] is False
    assert params["Z_wdot"]["collinear"] is True
    assert all(k not in params["Z:w"] for k in ("excited", "collinear"))


def test_asymptote_speed_error_counts_the_time_constant_and_the_f_tests_choice():
    """The steady speed of 1-Hz plateaus of 40 samples with a transient. Ten times the noise, τ a
    quarter of the run (always kept by the F test): the s.e. held τ fixed at the grid's best
    point and the ±1.96 s.e. band held 55 % of the speeds; with τ free in the Jacobian (n − 4
    degrees of freedom) 88 %. Three times the noise, τ a tenth of the run: the F test drops the
    transient in 17 % of draws, whose line slope the line's own s.e. did not cover (band 59 %;
    82 % with τ free on the kept ones alone); the exponential model's s.e. on both branches
    holds 92 %."""
    from nnid.trainers.caccia import _asymptote

    rng = np.random.default_rng(3)
    t = np.arange(40.0)
    sigma, speed = 0.01, 0.1
    for amplitude, tau in ((10 * sigma, 0.25 * t[-1]), (3 * sigma, 0.1 * t[-1])):
        inside = []
        for _ in range(100):
            x = 1.0 + speed * t + amplitude * np.exp(-t / tau) + rng.normal(0, sigma, t.size)
            value, se = _asymptote(t, x)
            inside.append(abs(value - speed) <= 1.96 * se)
        assert 0.88 <= np.mean(inside) <= 0.99, (amplitude, np.mean(inside))


def _leave_unidentified(monkeypatch, name: str) -> None:
    """Make every Caccia campaign fit leave parameter ``name`` unidentified (NaN), as a zero
    column would: the cases a campaign of the fixture cannot produce itself."""
    import dataclasses

    fit_logs = CacciaTwoStep.fit_logs

    def unidentified(self, *args, **kwargs):
        est = fit_logs(self, *args, **kwargs)
        theta = est.theta.copy()
        theta[est.names.index(name)] = np.nan
        return dataclasses.replace(est, theta=theta)

    monkeypatch.setattr(CacciaTwoStep, "fit_logs", unidentified)


def test_an_unidentified_installation_coefficient_is_flown_at_the_vehicle_files_value(
    setup, monkeypatch, tmp_path
):
    """A Caccia fit that leaves eta.w.neg unidentified (NaN) flew it at 0 (np.nan_to_num),
    without a word: no upward thrust at all. (Forced here: step 1 has no eta column for a
    group without plateaus, so a campaign does not leave it NaN; a zero column would.) It
    flies the vehicle file's value, as ParametricModel does, says so, and keeps it through a
    save; a file saved before that keeps 0, as it was fitted, and says so."""
    import json

    from nnid.errors import ExcitationWarning

    _, _, vehicle, log = setup
    _leave_unidentified(monkeypatch, "eta.w.neg")
    file_value = vehicle.installation["w.neg"]
    with (
        pytest.warns(UserWarning, match="step 2 did not run"),  # no sinusoid run: cheaper
        pytest.warns(ExcitationWarning, match=r"eta\.w\.neg at the vehicle file's value"),
    ):
        model = CacciaModel(vehicle).fit(log)
    assert file_value != 0 and model.parts_.eta_neg[2] == file_value
    assert model.params["eta.w.neg"]["simulated_at"] == file_value
    model.save(tmp_path)
    assert load_model(tmp_path).params == model.params
    path = tmp_path / "model.json"
    payload = json.loads(path.read_text())
    del payload["state"]["from_file"]
    path.write_text(json.dumps(payload))
    with pytest.warns(ExcitationWarning, match=r"predates .* at 0, .*: eta\.w\.neg"):
        older = load_model(tmp_path)
    assert older.parts_.eta_neg[2] == 0.0 and older.from_file_ == {"eta.w.neg": None}


def test_an_unidentified_weight_minus_buoyancy_is_flown_at_the_vehicle_files(
    setup, monkeypatch, tmp_path
):
    """A Caccia heave fit that leaves W − B unidentified (NaN) set the plant's buoyancy to
    W − NaN: every prediction NaN, unsaid. (Forced, as the installation coefficient above.) It
    flies the vehicle file's W − B (its weight and buoyancy), says so in the warning and in
    simulated_at, and keeps it through a save."""
    from nnid.errors import ExcitationWarning

    _, _, vehicle, log = setup
    _leave_unidentified(monkeypatch, "weight_minus_buoyancy")
    file_value = float(vehicle.weight - vehicle.buoyancy)
    with (
        pytest.warns(UserWarning, match="step 2 did not run"),  # no sinusoid run: cheaper
        pytest.warns(ExcitationWarning, match=r"weight_minus_buoyancy at the vehicle file's"),
    ):
        model = CacciaModel(vehicle).fit(log)
    assert file_value != 0 and model.parts_.buoyancy == vehicle.buoyancy
    entry = model.params["weight_minus_buoyancy"]
    assert entry["value"] is None and entry["simulated_at"] == pytest.approx(file_value)
    model.save(tmp_path)
    back = load_model(tmp_path)
    assert back.params == model.params and back.parts_.buoyancy == model.parts_.buoyancy
    # saved before 'from_file', it predicted NaN (a NaN buoyancy), not 0 as it flies now
    import json

    path = tmp_path / "model.json"
    payload = json.loads(path.read_text())
    del payload["state"]["from_file"]
    path.write_text(json.dumps(payload))
    with pytest.warns(ExcitationWarning) as said:
        older = load_model(tmp_path)
    words = " ".join(str(w.message) for w in said)
    assert "weight_minus_buoyancy at 0 (neutrally buoyant), where the saved model " in words
    assert "as it did when it was fitted" not in words
    assert older.parts_.buoyancy == older.parts_.weight


def test_force_to_commands_inverts_a_thrust_curve_that_turns_near_zero():
    """vlbv300's Weiss eq. 10 curve falls over 0 < |c| < 2.5 PWM before it rises: inverting it
    raised a raw "thrust curve of 'VS' is not monotone" (a traceback from nnid train on a
    caccia_campaign). It is inverted beyond that turn; a thrust inside it (below 0.026 N) is
    flown at the nearest the curve makes, and said; a force beyond the curve's reach, which
    np.interp flew at the limit while the report stated the design, is refused."""
    from nnid.errors import NnidInputError

    vehicle = load_vehicle("vlbv300")
    force = np.array([-100.0, -30.0, -1.0, 0.0, 0.5, 30.0, 100.0])
    tau = Actuation(vehicle).nominal(force_to_commands(vehicle, "w", force))
    np.testing.assert_allclose(tau[:, 2], force, atol=1e-3)
    with pytest.warns(UserWarning, match=r"'VS' makes no thrust between .* nearest thrust"):
        tiny = Actuation(vehicle).nominal(force_to_commands(vehicle, "w", np.array([0.01])))
    assert abs(tiny[0, 2] - 0.01) < 0.03  # within half the curve's gap of the design
    with pytest.raises(NnidInputError, match=r"thruster 'VS' for [\d.]+ N.*reaches"):
        force_to_commands(vehicle, "w", np.array([0.0, 150.0]))


def test_a_thrust_curve_of_another_shape_is_not_inverted_on_the_wrong_branches():
    """The inversion beyond a dip keeps the commands from each limit inwards while the thrust
    rises: right for sign(c)·g(|c|) dipping around 0 (Weiss eq. 10), wrong for a curve that
    rolls over at its limits (each branch was the limit alone: the rising middle thrown away)
    or a table with a dip away from 0 (thrusts no longer rising: wrong commands, unsaid).
    Neither is inverted."""
    from nnid.trainers.caccia import _monotone_branch

    grid = np.linspace(-10.0, 10.0, 2001)
    rolls_over = lambda c: 4.0 * c - 0.3 * c * np.abs(c) * np.abs(c) / 10.0  # noqa: E731
    assert np.any(np.diff(rolls_over(grid)) < 0)
    assert _monotone_branch(grid, rolls_over) is None
    dips_away = lambda c: np.interp(c, [-10, 0, 4, 5, 10], [-10, 0, 4, 3.5, 10])  # noqa: E731
    assert _monotone_branch(grid, dips_away) is None
    weiss = lambda c: np.sign(c) * (0.0684 - 0.03366 * np.abs(c) + 0.006736 * c * c)  # noqa: E731
    cmds, thrust = _monotone_branch(grid, weiss)
    assert np.all(np.diff(thrust) >= 0) and cmds[0] == -10.0 and cmds[-1] == 10.0
