"""The residual loop (issue 7): residual analysis, candidate effects, diagnosis end to end.

Each effect kind is injected at a material size into a simulated log of a vehicle whose file
does not declare it; the loop must add that effect first, estimate it within 10 %, and at
least halve the held-out free-run error. Logs without an undeclared effect must give no
effect. Vehicles: the Seamor preset (Weiss) and 'minirov', a made-up vehicle that is not a
preset (nnid/demo_data/minirov.toml).
"""

from __future__ import annotations

import json
from importlib import resources

import numpy as np
import pandas as pd
import pytest
from conftest import assert_labels_inside

from nnid.datasets.measurement import Measurement
from nnid.datasets.preprocess import first_order_lag
from nnid.loop.effects import Candidate, candidates
from nnid.loop.residual_loop import ResidualLoop
from nnid.loop.residuals import correlation_analysis
from nnid.loop.scenarios import effect_log
from nnid.physics.effects import parse_effect
from nnid.vehicle import load_vehicle

MINIROV = str(resources.files("nnid.demo_data").joinpath("minirov.toml"))


def _without(vehicle, key: str):
    data = vehicle.model_dump()
    del data["damping"]["coefficients"][key]
    return type(vehicle).model_validate(data)


# -- residual analysis ---------------------------------------------------------------------------
def test_white_residual_stays_in_the_99_percent_band(rng):
    e = rng.normal(size=20_000)
    u = rng.normal(size=20_000)
    c = correlation_analysis(e, {"tau_X": u})
    assert c.auto[0] == pytest.approx(1.0)
    assert c.band == pytest.approx(2.5758 / np.sqrt(20_000), rel=1e-3)
    assert c.auto_outside <= 0.12  # 1 % expected; 25 lags
    assert c.cross_outside()["tau_X"] <= 0.12


def test_correlation_analysis_finds_structure_and_the_input_lag(rng):
    u = rng.normal(size=20_000)
    # a residual that still depends on the input 3 samples ago, plus coloured noise
    noise = np.convolve(rng.normal(size=20_000), np.ones(5) / 5, mode="same")
    e = 0.5 * np.roll(u, 3) + noise
    e[:3] = 0.0
    c = correlation_analysis(e, {"tau_X": u}, max_lag=25)
    assert c.auto_outside > 0.1  # lags 1-4 from the moving average
    lag = int(c.lags[np.argmax(np.abs(c.cross["tau_X"]))])
    assert lag == 3
    # lagged products never join two experiments
    exp = np.repeat([0, 1], 10_000)
    spikes = rng.normal(0, 0.01, 20_000)
    spikes[9_999] = spikes[10_000] = 10.0  # the end of one run and the start of the next
    joined = correlation_analysis(spikes, {}, max_lag=2)
    apart = correlation_analysis(spikes, {}, exp, max_lag=2)
    assert joined.auto[1] > 0.4
    assert abs(apart.auto[1]) < 0.05


@pytest.mark.parametrize("n_dofs", [1, 6])
def test_correlation_grid_keeps_every_label_inside_the_figure(rng, monkeypatch, n_dofs):
    """The report's correlation grid has fixed margins (no layout engine): every panel's
    tick labels, axis labels, title and legend must still lie inside the figure and out of
    the other panels, from one DOF to six."""
    from nnid.reports import loop_report

    built = []
    real_uri = loop_report.figure_uri
    monkeypatch.setattr(loop_report, "figure_uri", lambda fig: built.append(fig) or real_uri(fig))
    e, u = rng.normal(size=(2, 5_000))
    c = correlation_analysis(e + 0.5 * np.roll(u, 3), {"tau_Z": u, "tau_N": -u})
    uri = loop_report.correlation_figure(dict.fromkeys("uvwpqr"[:n_dofs], c), "baseline")
    assert uri.startswith("data:image/png;base64,")
    (fig,) = built
    assert_labels_inside(fig)


@pytest.mark.parametrize(("n_dofs", "amplitude", "longest"), [(6, 3e-4, 7), (1, 1e6, 2)])
def test_free_run_figure_draws_once_with_every_label_inside(
    monkeypatch, n_dofs, amplitude, longest
):
    """The held-out free-run figure has fixed margins (the constrained layout drew it twice):
    its velocity tick labels, unbounded unlike a correlation's, still fit, from a DOF barely
    moving (labels of seven or eight characters, -0.00050) to a diverged run (an offset, 1e6)."""
    from nnid.reports import loop_report

    built = []
    real_uri = loop_report.figure_uri
    monkeypatch.setattr(loop_report, "figure_uri", lambda fig: built.append(fig) or real_uri(fig))
    t = np.arange(600) * 0.1
    dofs = list("uvwpqr"[:n_dofs])
    measured = pd.DataFrame({d: amplitude * np.sin(t / 7) for d in dofs})
    uri = loop_report.free_run_figure(t, measured, 1.1 * measured, 0.9 * measured, dofs)
    assert uri.startswith("data:image/png;base64,")
    (fig,) = built
    assert_labels_inside(fig)
    # the case asked for: labels this long (an offset, 1e6, keeps the diverged run's short)
    assert max(len(x.get_text()) for x in fig.axes[0].get_yticklabels()) >= longest


# -- candidates ------------------------------------------------------------------------------------
def test_first_order_lag_is_exact_for_held_inputs():
    log = pd.DataFrame({"t": np.arange(400) * 0.05})
    tau = np.zeros((400, 6))
    tau[100:, 2] = 2.0
    a = first_order_lag(tau, log, 0.3)
    k = np.arange(100, 400)
    assert np.allclose(a[k, 2], 2.0 * (1 - np.exp(-(k - 100) * 0.05 / 0.3)))
    assert np.all(a[:100] == 0.0)


def test_candidates_cover_the_vocabulary_and_skip_what_is_declared():
    veh = load_vehicle(MINIROV)
    log = effect_log(veh, duration=60, n_experiments=1, seed=3)
    names = {c.name for c in candidates(veh, log)}
    kinds = {parse_effect(n)[0] for n in names}
    assert kinds == {
        "coupled_damping",
        "thruster_installation",
        "buoyancy_offset",
        "restoring_offset",
        "external_bias",
        "added_mass",
        "current",
        "actuator_lag",
        "thruster_deadband",
    }  # linear and quadratic damping of every DOF are declared in minirov
    assert "linear_damping.u" not in names and "quadratic_damping.u" not in names
    assert "coupled_damping.N:v*abs(r)" in names
    assert all("(eta-1)" not in n for n in names)  # duplicates of other terms when u_c = 0
    assert "linear_damping.u" in {c.name for c in candidates(_without(veh, "X:u"), log)}


def test_installation_value_is_relative_to_the_declared_coefficient():
    veh = load_vehicle(MINIROV).model_copy(update={"installation": {"w.neg": 0.8}})
    c = Candidate("thruster_installation.w.neg", "thruster_installation", "eta.w.neg")
    assert c.value(-0.2, veh) == pytest.approx(0.75)
    assert c.value_scale(veh) == pytest.approx(1.25)
    assert c.augment(veh, 0.5).installation["w.neg"] == pytest.approx(0.4)


# -- the loop on injected effects ----------------------------------------------------------------
CASES = [
    # vehicle, effect, value, speed (m/s; list: slow and fast runs), coefficient to remove
    ("seamor", "thruster_installation.w.neg", 0.6, 0.4, None),
    ("minirov", "thruster_installation.u.pos", 0.7, 0.4, None),
    # low speed, so a tank-grade velocity (2 mm/s noise): at 0.1 m/s a 5 mm/s DVL's noise
    # alone is 15 % of the signal in every DOF, and no model can halve such a free-run error
    ("minirov", "linear_damping.u", -30.0, (0.1, 0.2), "X:u"),
    ("seamor", "restoring_offset.M", 0.02, 0.4, None),
    ("minirov", "restoring_offset.M", 0.015, 0.4, None),
    ("minirov", "current.y", 0.15, 0.4, None),
    ("seamor", "buoyancy_offset", 4.0, 0.4, None),
    ("minirov", "coupled_damping.N:u*v", -5.0, 0.4, None),
    ("seamor", "coupled_damping.N:v", -1.0, 0.4, None),
    ("seamor", "actuator_lag", 0.3, 0.4, None),
    # beyond the seven kinds the issue names
    ("seamor", "thruster_deadband", 3.0, 0.4, None),
    ("minirov", "external_bias.v", 4.0, 0.4, None),
    ("seamor", "added_mass.w", -30.0, 0.4, None),
]


@pytest.mark.parametrize(("vehicle", "effect", "value", "speed", "drop"), CASES)
def test_loop_finds_the_injected_effect(vehicle, effect, value, speed, drop):
    veh = load_vehicle(MINIROV if vehicle == "minirov" else vehicle)
    if drop:
        veh = _without(veh, drop)
    noise = 0.002 if effect.startswith("linear") else 0.005
    meas = Measurement(kind="dvl_imu", velocity_noise=noise)
    log = effect_log(
        veh, [(effect, value)], duration=300, dt=0.05, speed=speed, seed=11, measurement=meas
    )
    loop = ResidualLoop(veh, max_effects=2).fit(log)
    assert loop.added_, f"nothing added; top: {loop.steps_[0].ranked[0].as_dict()}"
    first = loop.added_[0]
    # restoring_offset.K and .M are one physical change (z_g), named by where it shows most
    assert parse_effect(first.name)[0] == parse_effect(effect)[0]
    if parse_effect(effect)[0] != "restoring_offset":
        assert first.name == effect
    assert first.value == pytest.approx(value, rel=0.10)
    assert first.stderr > 0
    before = loop.before_["free_run_nrmse"]["total"]
    after = loop.after_["free_run_nrmse"]["total"]
    assert after <= 0.5 * before, (before, after)
    result = loop.as_dict()
    assert result["added"][0] == first.name
    assert result["unexplained"] == {}, result["unexplained"]  # the vocabulary explained it
    assert result["candidates"][0]["improvement"] >= result["candidates"][1]["improvement"]


@pytest.mark.parametrize("vehicle", ["seamor", "minirov"])
def test_no_undeclared_effect_gives_no_effect_in_19_of_20_seeds(vehicle):
    veh = load_vehicle(MINIROV if vehicle == "minirov" else vehicle)
    added, unexplained = [], []
    for seed in range(20):
        log = effect_log(veh, duration=180, dt=0.05, n_experiments=3, seed=100 + seed)
        loop = ResidualLoop(veh, max_effects=1).fit(log)
        added.append(loop.added)
        unexplained.append(loop.as_dict()["unexplained"])
    assert sum(bool(a) for a in added) <= 1, added
    assert sum(bool(u) for u in unexplained) <= 1, unexplained  # a clean log: noise only


DVL = Measurement(kind="dvl_imu", velocity_noise=0.005)


def _dropouts(log: pd.DataFrame, share: float, rng: np.random.Generator) -> pd.DataFrame:
    """The DVL's u v w emptied in bursts of 0.2-2 s until ``share`` of the samples is gone;
    depth, attitude and the gyro go on."""
    missing = np.zeros(len(log), dtype=bool)
    while missing.mean() < share:
        n = round(rng.uniform(0.2, 2.0) / 0.05)
        start = rng.integers(0, len(log) - n)
        missing[start : start + n] = True
    out = log.copy()
    out.loc[missing, ["u", "v", "w"]] = np.nan
    return out


def test_velocity_dropouts_give_the_same_diagnosis_and_are_reported():
    from nnid.reports.loop_report import summary

    veh = load_vehicle(MINIROV)
    effect = ("thruster_installation.u.pos", 0.7)
    log = effect_log(veh, [effect], duration=180, n_experiments=3, seed=11, measurement=DVL)
    complete = ResidualLoop(veh, max_effects=2).fit(log)
    gappy = ResidualLoop(veh, max_effects=2).fit(_dropouts(log, 0.05, np.random.default_rng(0)))
    assert gappy.added == complete.added == [effect[0]]
    a, b = complete.added_[0], gappy.added_[0]
    assert abs(a.value - b.value) < 2 * np.hypot(a.stderr, b.stderr)
    result = gappy.as_dict()
    gaps = result["data"]["gaps"]
    assert gaps["samples"] >= 0.05 * len(log) and 0.2 <= gaps["longest_s"] <= 2.1
    # no pose x, y: nothing to bridge u v w from, so every gap is masked and counted
    assert result["data"]["rows_masked"] >= gaps["samples"]
    assert summary(result)[0].startswith(f"The log misses motion data in {gaps['count']} gaps")
    assert complete.as_dict()["data"]["gaps"]["count"] == 0


def test_a_gap_no_step_touched_is_said_as_such():
    """A gap in a column the analysis neither bridges nor masks (depth, with velocities logged)
    is said with its column, not as an empty list (": .")."""
    from nnid.reports.loop_report import _gaps_line

    data = {
        "gaps": {"count": 1, "seconds": 0.1, "longest_s": 0.1,
                 "gaps": [{"experiment": "run0", "t": 2.0, "columns": ["z"]}]},
        "cleaning": [{"step": "derive accelerations", "detail": "du ... dr"}],
    }  # fmt: skip
    (line,) = _gaps_line(data)
    assert line.endswith("left as they are in z: no step bridged or masked them."), line
    data["cleaning"].append({"step": "mask gaps", "detail": "1 gaps in z masked"})
    assert _gaps_line(data)[0].endswith("(0.1 s missing, longest 0.1 s): 1 gaps in z masked.")


def _tug(t, forces):  # a tether pulling sideways every 9 s
    out = np.zeros_like(forces)
    out[:, 1] = 6.0 * np.sin(2 * np.pi * t / 9.0)
    return out


def _payload_drop(t, forces):  # 5 N of ballast lost halfway through each run
    out = np.zeros_like(forces)
    out[:, 2] = np.where(t > t[-1] / 2, 5.0, 0.0)
    return out


def _thrust_distortion(t, forces):  # a surge thrust curve that is not a scaled copy
    out = np.zeros_like(forces)
    x = forces[:, 0]
    out[:, 0] = 0.6 * x * np.abs(x) / np.abs(x).max()
    return out


@pytest.mark.parametrize(
    ("disturbance", "dof"), [(_tug, "v"), (_payload_drop, "w"), (_thrust_distortion, "u")]
)
def test_an_effect_outside_the_vocabulary_is_reported_as_unexplained(disturbance, dof):
    """Forces that act on the plant but that no vocabulary effect describes: the loop must say
    that structure remains in that DOF (naming its correlates), whatever it added."""
    from nnid.reports.loop_report import summary

    veh = load_vehicle(MINIROV)
    log = effect_log(
        veh, duration=180, n_experiments=3, seed=1, measurement=DVL, unlogged=disturbance
    )
    result = ResidualLoop(veh, max_effects=2).fit(log).as_dict()
    assert dof in result["unexplained"], result["unexplained"]
    assert "outside the vocabulary" in result["unexplained"][dof]
    assert result["unexplained_correlates"][dof][0]["correlation"] ** 2 > 0.06
    lines = summary(result)
    said = [line for line in lines if "outside the vocabulary" in line]
    assert said and (not result["added"] or said[0].startswith("The added effects explain part"))


def test_a_diverged_baseline_is_said_and_compared_like_for_like():
    """The demo log cut to one run (issue 13): the baseline refitted on 70 % of it diverges in
    free run on the rest. The loop must say so, judge and report on a horizon where the
    baseline does not diverge (never "diverged before, 0.059 after"), and still find the
    injected effect."""
    from nnid.datasets.readers import load_log
    from nnid.reports.loop_report import error_rows, summary

    root = resources.files("nnid.demo_data")
    log, _ = load_log(str(root.joinpath("demo_minirov_heave.parquet")))
    one = log[log["experiment"] == "run0"].reset_index(drop=True)
    result = ResidualLoop(load_vehicle(MINIROV)).fit(one).as_dict()
    before, after = result["before"], result["after"]
    assert before["free_run_nrmse"]["total"] is None and before["diverged"]
    assert result["steps"][0]["gate"] in ("1 s ahead", "one step")
    assert result["added"] == ["thruster_installation.w.neg"]
    for key in ("k_step_nrmse", "one_step_nrmse"):  # no held-out error gets worse
        if before[key]["total"] is not None:
            assert after[key]["total"] <= before[key]["total"]
    lines = summary(result)
    assert any("the baseline's held-out free run diverges" in line for line in lines)
    # its 1 s-ahead score diverged too: loop.json said null with no why, the table "-"
    assert before["k_step_nrmse"]["total"] is None and before["k_step_diverged"]
    rows = {r[0]: r for r in error_rows(result)[1]}
    assert rows["1 s-ahead velocity NRMSE, before"][-1] == "diverged"
    total = lines[-1]
    assert total.startswith("Total held-out one-step NRMSE") or "1 s-ahead" in total
    assert "- before" not in total
    assert not any("stays above 1" in line for line in lines)
    # an after above 1 (Haizhe's heave: 1.26 to 1.13) is a fall without skill: said
    key = "one_step_nrmse" if total.startswith("Total held-out one-step") else "k_step_nrmse"
    before[key]["total"], after[key]["total"] = 1.26, 1.13
    lines = summary(result)
    assert "stays above 1 after" in lines[-2] and lines[-1].endswith(
        f"1.26 before, 1.13 after ({result['added'][0]} added)."
    )


def test_the_error_table_says_a_diverged_k_step_or_one_step_score():
    """Only the free run's diverged DOFs were read: a k-step score that diverged showed "-",
    the cell of an error that was not measured."""
    from nnid.reports.loop_report import error_rows

    def errors(k_step, gone):
        return {"free_run_nrmse": {"w": 0.2, "total": 0.2}, "diverged": {},
                "k_step_nrmse": {"w": k_step, "total": k_step}, "k_step_diverged": gone,
                "one_step_nrmse": {"w": 0.1, "total": 0.1}, "one_step_diverged": {}}  # fmt: skip

    result = {"settings": {"k_step_s": 1.0}, "before": errors(None, {"w": 3.2}),
              "after": errors(None, {})}  # fmt: skip
    rows = {r[0]: r for r in error_rows(result)[1]}
    assert rows["1 s-ahead velocity NRMSE, before"][3:] == ["diverged", "-", "-", "-", "diverged"]
    # None and not diverged: nothing was left to score (not "diverged", not a bare "-")
    assert rows["1 s-ahead velocity NRMSE, after"][3] == "not scored"
    assert rows["free-run velocity NRMSE, before"][3] == "0.2"


def test_loop_scores_never_count_the_measurement_a_prediction_starts_from():
    """The first k samples of a k-step prediction repeat the measurement: scored whenever
    ``warmup_s`` was shorter than the horizon (a 5 s gate after a 2 s warm-up), as perfect
    predictions. The score is now the same whether the warm-up covers them or not."""
    from nnid.datasets.readers import load_log
    from nnid.loop.diagnose import velocity_scores

    root = resources.files("nnid.demo_data")
    log, _ = load_log(str(root.joinpath("demo_minirov_heave.parquet")))
    one = log[log["experiment"] == "run0"].reset_index(drop=True)
    data = load_vehicle(MINIROV).model_dump()
    data["damping"]["coefficients"]["Z:w"] *= 0.5  # a model with an error to score
    wrong = type(load_vehicle(MINIROV)).model_validate(data)
    dt, k = float(np.median(np.diff(one["t"]))), 40
    bare = velocity_scores(wrong, one, k, 0.0, ("w",))[0]["w"]
    covered = velocity_scores(wrong, one, k, (k - 0.5) * dt, ("w",))[0]["w"]
    assert bare == pytest.approx(covered, rel=1e-12)


# -- CLI -----------------------------------------------------------------------------------------
def test_cli_demo_reports_the_injected_heave_thrust_loss(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    import nnid.runs
    from nnid.cli import app

    outcomes = []
    real = nnid.runs.residual_loop_run

    def spy(*args, **kwargs):
        outcomes.append(real(*args, **kwargs))
        return outcomes[-1]

    monkeypatch.setattr(nnid.runs, "residual_loop_run", spy)
    res = CliRunner().invoke(app, ["demo", "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    result = json.loads((tmp_path / "loop.json").read_text())
    # the held-out runs that measured "after" ranked and gated the effect: said in loop.json,
    # the batch headline and the printed summary, the README's quoted line left whole
    (outcome,) = outcomes
    used = result["validation_used_for"]
    assert "ranking" in used and "choosing" in used
    assert outcome.headline["validation_used_for"] == used
    lines = outcome.lines
    first = next(i for i, line in enumerate(lines) if line.startswith("Upward heave thrust is"))
    assert lines[first].endswith("(NRMSE).")
    assert "not an independent test" in lines[first + 1]
    note = next(t for t in (tmp_path / "report.md").read_text().splitlines() if "gate" in t)
    assert "ranked the candidates" in note and "not an independent test" in note
    for key in ("baseline", "before", "candidates", "added", "after"):
        assert key in result
    assert result["added"][0] == "thruster_installation.w.neg"
    first = result["candidates"][0]
    assert first["params"]["value"] == pytest.approx(0.57, rel=0.1)
    assert {"effect", "params", "stderr", "significance", "improvement"} <= set(first)
    assert result["after"]["free_run_nrmse"]["w"] < 0.5 * result["before"]["free_run_nrmse"]["w"]
    assert "Upward heave thrust is" in res.output
    html = (tmp_path / "report.html").read_text()
    assert html.count("data:image/png;base64,") == 3
    assert "Upward heave thrust" in (tmp_path / "report.md").read_text()
    # a heave-only log has u = v = 0, so V = |w| and Vw = w: these two are one column
    same = {c["effect"]: c["same_column_as"] for c in result["steps"][0]["top"]}
    assert same["coupled_damping.Z:abs(w)*V"] == ["coupled_damping.Z:w*Vw"]
    assert same["coupled_damping.Z:w*Vw"] == ["coupled_damping.Z:abs(w)*V"]
    assert same["thruster_installation.w.neg"] == []
    assert (
        "coupled_damping.Z:w*Vw (= coupled_damping.Z:abs(w)*V)"
        in (tmp_path / "report.md").read_text()
    )


def test_the_loop_runs_with_one_blas_thread_and_gives_the_callers_back(monkeypatch):
    """The loop's work runs with one thread per BLAS library (a second one only spins on its
    small products: nnid.threads.blas_threads), and the caller's count is back after it."""
    from threadpoolctl import threadpool_info, threadpool_limits

    def blas():
        return [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]

    seen = []
    monkeypatch.setattr(ResidualLoop, "_fit", lambda self, log, say: seen.append(blas()))
    log = pd.read_parquet(resources.files("nnid.demo_data").joinpath("demo_minirov_heave.parquet"))
    with threadpool_limits(limits=2, user_api="blas"):  # the caller's (tests run with one)
        caller = blas()
        ResidualLoop(load_vehicle(MINIROV)).fit(log)
        after = blas()
    assert caller and set(caller) == {2}, caller
    assert seen and set(seen[0]) == {1}, seen
    assert after == caller


def test_cli_loop_bad_input_exits_2_naming_the_column(tmp_path):
    from typer.testing import CliRunner

    from nnid.cli import app

    log = effect_log(load_vehicle("seamor"), duration=30, n_experiments=1, seed=1)
    path = tmp_path / "log.csv"
    log.drop(columns=["tau_Z"]).to_csv(path, index=False)
    res = CliRunner().invoke(
        app, ["loop", "--data", str(path), "--vehicle", "seamor", "--out", str(tmp_path / "o")]
    )
    assert res.exit_code == 2
    assert "tau_Z" in res.output


def test_cli_loop_config_on_the_rotational_dofs_only(tmp_path):
    """A log without u v w (no DVL): the loop is asked for p q r only, held-out runs named in a
    config; it finds the undeclared centre-of-gravity offset from roll and pitch alone."""
    from typer.testing import CliRunner

    from nnid.cli import app
    from nnid.datasets.simulator import simulate
    from nnid.loop.scenarios import force_amplitudes, multisine_forces

    veh = load_vehicle("seamor")
    rng = np.random.default_rng(5)
    amp = force_amplitudes(veh, 0.4)
    amp[:3] = 0.0  # moments only: nothing drives u v w, so the attitude equations are exact
    runs = [
        simulate(
            veh,
            multisine_forces(1000, 0.05, amp, rng),
            0.05,
            effects=[("restoring_offset.M", 0.02)],
            measurement=Measurement(kind="dvl_imu"),
            seed=k,
            experiment=f"run{k}",
        ).drop(columns=["u", "v", "w"])
        for k in range(5)
    ]
    pd.concat(runs, ignore_index=True).to_parquet(tmp_path / "log.parquet")
    (tmp_path / "loop.toml").write_text(
        'kind = "loop"\nvehicle = "seamor"\ndofs = ["p", "q", "r"]\ngate_horizon_s = 2.0\n'
        'validation = ["run3", "run4"]\nmax_effects = 2\n[data]\nlog = "log.parquet"\n'
    )
    res = CliRunner().invoke(app, ["loop", str(tmp_path / "loop.toml"), "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    result = json.loads((tmp_path / "loop.json").read_text())
    assert result["settings"]["dofs"] == ["p", "q", "r"]
    assert set(result["before"]["free_run_nrmse"]) <= {"p", "q", "r", "total"}
    held = {p["experiment"] for p in result["settings"]["split"]["parts"]["validation"]}
    assert held == {"run3", "run4"}
    assert result["added"] and result["added"][0].startswith("restoring_offset.")
    assert result["candidates"][0]["params"]["value"] == pytest.approx(0.02, rel=0.1)
    # the gate was the 2 s-ahead simulation the config asked for, not the free run
    assert result["settings"]["gate_horizon_s"] == 2.0
    gate = result["steps"][0]["added"]["gate_nrmse"]
    assert gate["before"] < result["before"]["free_run_nrmse"]["total"]
    assert gate["after"] < gate["before"]


def test_loop_finds_caccias_upward_thrust_loss_through_the_thrusters():
    """Caccia's own case (section IV-D, Table II): ROMEO's heave stairs logged as thruster
    commands, the vehicle file without its installation coefficients; the loop must say that
    upward heave thrust is 56 % of nominal (held steps: the test also needs the F-test to use
    the residual of the model with the effect, not the baseline's, which the missing effect
    keeps correlated over whole steps)."""
    from pathlib import Path

    from nnid.config import SimulateConfig, load_config
    from nnid.datasets.simulator import simulate_config

    root = Path(__file__).resolve().parents[1]
    cfg = load_config(root / "configs/romeo_heave.toml", SimulateConfig)
    cfg.experiments = [e for e in cfg.experiments if e.name == "weight0"]
    romeo = load_vehicle("romeo")
    log = simulate_config(cfg, romeo)
    assert "cmd_VFL" in log and "tau_Z" not in log
    declared = romeo.model_copy(update={"installation": {}})
    loop = ResidualLoop(declared, dofs=("w",), max_effects=1).fit(log)
    assert loop.added == ["thruster_installation.w.neg"]
    assert loop.added_[0].value == pytest.approx(0.56, rel=0.05)
    assert loop.after_["free_run_nrmse"]["w"] < 0.5 * loop.before_["free_run_nrmse"]["w"]


def test_cli_loop_options_choose_dofs_held_out_and_excluded_runs(tmp_path):
    """The on-your-data form without a config: --dofs, --validation and --exclude."""
    from typer.testing import CliRunner

    from nnid.cli import app

    veh = load_vehicle(MINIROV)
    log = effect_log(veh, duration=120, n_experiments=4, seed=5, measurement=DVL)
    path = tmp_path / "log.csv"
    log.to_csv(path, index=False)
    runner = CliRunner()
    args = ["loop", "--data", str(path), "--vehicle", MINIROV, "--max-effects", "0"]
    res = runner.invoke(
        app, [*args, "--dofs", "w,r", "--validation", "run2", "--exclude", "run1", "--out",
              str(tmp_path / "o")],
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    result = json.loads((tmp_path / "o" / "loop.json").read_text())
    parts = result["settings"]["split"]["parts"]
    assert result["settings"]["dofs"] == ["w", "r"]
    assert [p["experiment"] for p in parts["validation"]] == ["run2"]
    assert [p["experiment"] for p in parts["train"]] == ["run0", "run3"]
    assert "left out run1" in (tmp_path / "o" / "cleaning.md").read_text()
    assert not [w for w in result["warnings"] if "rough reading" in w]
    # a held-out run of 5 s: 60 scored samples, ~2 independent ones at the residual's
    # correlation time; its before/after was reported with no word on how little it rests on
    start = log.loc[log["experiment"] == "run2", "t"].min()
    short = log[(log["experiment"] != "run2") | (log["t"] < start + 5.0)]
    short.to_csv(tmp_path / "short.csv", index=False)
    res = runner.invoke(
        app, [args[0], "--data", str(tmp_path / "short.csv"), *args[3:], "--validation",
              "run2", "--out", str(tmp_path / "s")],
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    said = json.loads((tmp_path / "s" / "loop.json").read_text())["warnings"]
    assert [w for w in said if "rest on 60 samples after the warm-up, about 2 independent" in w]
    for report in ("report.md", "report.html"):  # the reports showed no loop warning at all
        assert "about 2 independent ones" in (tmp_path / "s" / report).read_text()
    assert "## Warnings" not in (tmp_path / "o" / "report.md").read_text()
    for bad, name in (("--dofs", "w,x"), ("--exclude", "run9"), ("--validation", "run9")):
        res = runner.invoke(app, [*args, bad, name, "--out", str(tmp_path / "bad")])
        assert res.exit_code == 2 and name.split(",")[-1] in res.output, res.output
        assert not (tmp_path / "bad").exists()
    # an option that names nothing is refused, not read as "all"
    res = runner.invoke(app, [*args, "--dofs", ",", "--out", str(tmp_path / "x")])
    assert res.exit_code == 2 and "'--dofs': names nothing" in res.output, res.output
    # every run left out: said against --exclude, not as a held-out run of 0 s against warmup_s
    res = runner.invoke(
        app, [*args, "--exclude", "run0,run1,run2,run3", "--out", str(tmp_path / "x")]
    )
    assert res.exit_code == 2 and "'--exclude': leaves no experiment" in res.output, res.output
    # a held-out run that --exclude left out, and one not in the log: said against the option
    # (they were "validation experiments not in the log", against the log file)
    for held, why in (("run1", "is left out by --exclude"), ("run9", "is not in the log")):
        res = runner.invoke(
            app, [*args, "--exclude", "run1", "--validation", held, "--out", str(tmp_path / "x")]
        )
        said = f"error: field '--validation': experiment '{held}' {why}"
        assert res.exit_code == 2 and said in res.output, res.output


def test_search_intervals_stay_where_a_vehicle_file_may_hold_the_value():
    """A fast vehicle (8 m/s) logged at 1 Hz: the current is searched within the vehicle
    file's ±10 m/s and the actuator lag within its 60 s, so no trial vehicle is refused."""
    from nnid.vehicle import MAX_CURRENT, MAX_LAG

    veh = load_vehicle(MINIROV)
    log = effect_log(veh, duration=30, n_experiments=1, seed=3).iloc[::20].reset_index(drop=True)
    log["u"] = 8.0 * np.sin(0.1 * log["t"])
    found = {c.name: c.bounds for c in candidates(veh, log)}
    assert np.median(np.diff(log["t"])) == pytest.approx(1.0)
    assert found["current.x"] == (-MAX_CURRENT, MAX_CURRENT)
    assert found["actuator_lag"] == (0.0, MAX_LAG)
    for name in ("current.x", "actuator_lag"):
        Candidate(name, name.split(".")[0], bounds=found[name]).augment(veh, found[name][1])


def test_each_added_effect_is_reported_as_the_final_model_holds_it():
    """Two nearly collinear effects (4 N too heavy, a 3 N downward pull): the second pass's
    joint refit moves the first one's value by several of its pass's standard errors. The
    report gives each effect as the final model (the one "after" is scored on) holds it, within
    3 s.e. of the truth, the pass's own value beside it; stopped at max_effects = 1 it says so
    and does not call what remains "outside the vocabulary"."""
    from nnid.physics.parts import Parts
    from nnid.reports.loop_report import markdown

    veh = load_vehicle(MINIROV)
    truth = [("buoyancy_offset", 4.0), ("external_bias.w", 3.0)]
    log = effect_log(veh, truth, duration=240.0, dt=0.1, n_experiments=4, seed=2)
    loop = ResidualLoop(veh, max_effects=2).fit(log)
    result = loop.as_dict()
    assert result["added"] == ["buoyancy_offset", "external_bias.w"]
    assert result["stopped"] == "max_effects"
    for step, (_, value) in zip(result["steps"], truth, strict=True):
        added = step["added"]
        assert added["from"] == "the final joint refit"
        assert abs(added["params"]["value"] - value) < 3 * added["stderr"]["value"], added
    first = result["steps"][0]["added"]
    k = loop.fit_.unknowns.index(loop.added_[0].candidate.parameter)
    base = Parts.from_vehicle(veh).get(loop.added_[0].candidate.parameter)
    assert first["params"]["value"] == pytest.approx(-(loop.fit_.theta[k] - base), rel=1e-12)
    moved = abs(first["pass_params"]["value"] - first["params"]["value"])
    assert moved > 2 * first["stderr"]["value"]  # the pass's value is not the final one
    one = ResidualLoop(veh, max_effects=1).fit(log).as_dict()
    assert one["stopped"] == "max_effects"
    text = markdown(one)
    assert "stopped at max_effects = 1" in text and "outside the vocabulary" not in text
    # the gate chose the effect on the held-out runs that score it: said, not implied away
    assert "not an independent test" in text
    none = markdown(ResidualLoop(veh, max_effects=0).fit(log).as_dict())
    assert "No effect was tested (max_effects = 0)" in none and "No significant" not in none
    assert "not an independent test" not in none


@pytest.mark.parametrize("seed", [0, 4])
def test_an_added_effect_is_weighed_by_the_model_that_has_it(seed):
    """A centre of gravity 7 cm higher than the file says: with the baseline's weights kept,
    the roll and pitch equations (whose residual the missing restoring moment made thousands
    of times the final one) were weighed down, r_g.z came 1 mm off from the noisy surge and
    sway rows, and the unexplained-structure test blamed that on an effect outside the
    vocabulary. The weights are renewed after each added effect: the value to the half
    millimetre, its s.e. covering the error, nothing unexplained."""
    veh = load_vehicle(MINIROV).model_copy(update={"r_g": [0.0, 0.0, 0.09]})
    log = effect_log(veh, [("restoring_offset.M", -0.07)], duration=300, dt=0.05, seed=seed,
                     measurement=Measurement(kind="dvl_imu", velocity_noise=0.005))  # fmt: skip
    result = ResidualLoop(veh).fit(log).as_dict()
    assert [a.split(".")[0] for a in result["added"]] == ["restoring_offset"]
    added = result["steps"][0]["added"]
    value, se = added["params"]["value"], added["stderr"]["value"]
    assert value == pytest.approx(-0.07, abs=5e-4) and abs(value + 0.07) < 3 * se < 1e-3
    assert result["unexplained"] == {}, result["unexplained"]


def test_a_negative_restoring_offset_is_never_described_as_lower():
    """An effect's meaning is one line per kind, written before its value is known. That of
    restoring_offset said "the centre of gravity sits lower than declared" whatever the sign:
    loop.json carried it beside the Liu BlueROV's −0.018 m (a centre of gravity higher than
    declared), and the hybrid's opinion printed it raw. It names the quantity and its sign
    convention; the report's sentence says the direction, from the value."""
    from nnid.reports.loop_report import effect_sentence, hybrid_opinion

    cand = Candidate("restoring_offset.M", "restoring_offset", "r_g.z", dofs=("p", "q"))
    assert "lower than" not in cand.meaning and "higher than" not in cand.meaning
    assert "z_g; + is lower" in cand.meaning
    step = {"effect": cand.name, "meaning": cand.meaning,
            "params": {"value": -0.0177}, "stderr": {"value": 0.0022}}  # fmt: skip
    assert "higher than the vehicle file says" in effect_sentence(step)
    assert "lower than" not in effect_sentence(step)
    term = {"effect": cand.name, "meaning": cand.meaning, "value": -0.0177, "share": 0.6}
    opinion = {"terms": [term], "explained": 0.6, "force_rms": {"p": 0.1, "q": 0.2}}
    assert "lower than" not in hybrid_opinion({"hybrid_opinion": opinion, "added": []})


def test_a_noisy_dof_keeps_its_own_stderr_beside_an_exact_one(monkeypatch):
    """The loop's weights are feasible least squares' (1/σ̂²_dof, each σ̂² floored where it is
    rounding, spread within 1/√eps) and each DOF's RSS share is floored on its own. Beside a
    surge equation of exact data (X:u = 1 read off u ~ 1e3, σ̂² 3e-27: rounding) the weights
    were 1/σ̂², 3e26 on surge, and the pooled RSS was its rounding floor: N:r came out
    1.93 ± 9.5e6 where its own equation measures it to 0.032. The columns are given directly."""
    import warnings
    from types import SimpleNamespace

    import nnid.loop.diagnose as diagnose

    rng = np.random.default_rng(0)
    n = 1000
    u, r = rng.integers(500, 2000, size=n).astype(float), rng.normal(size=n)
    phi = np.zeros((n, 6, 2))
    phi[:, 0, 0], phi[:, 5, 1] = u, r
    y = rng.normal(size=(n, 6))  # sway to pitch: unit noise, no unknown
    y[:, 0], y[:, 5] = u, 2.0 * r + y[:, 5]
    e = y[:, 5] - r * (r @ y[:, 5]) / (r @ r)
    se_alone = np.sqrt(e @ e / (n - 1) / (r @ r))  # N:r's s.e. from yaw's own rows
    from nnid.physics.dofs import DOFS
    from nnid.trainers.regression import Regression

    regression = Regression(phi.reshape(n * 6, 2), y.reshape(-1), ["X:u", "N:r"], DOFS, n)
    monkeypatch.setattr(diagnose, "_regression", lambda *args: regression)
    ws = SimpleNamespace(arrays=lambda *args: {}, filter_lambda=None, nu_dot_f=lambda part: None,
                         mask=np.ones(6), weights=None)  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fit = diagnose.refit(ws, load_vehicle(MINIROV), ["X:u", "N:r"], held_out=False)
        again = diagnose.reweight(ws, fit)  # weights from the fit's own residual and targets
    for f in (fit, again):
        assert f.theta[0] == pytest.approx(1.0, rel=1e-12) and 0 < f.stderr[0] < 1e-8
        assert f.theta[1] == pytest.approx(2.0, abs=4 * se_alone)
        assert f.stderr[1] == pytest.approx(se_alone, rel=0.02)
    # a DOF the log does not measure sets no floor: a huge residual there moves no weight
    weights, e = ws.weights.copy(), again.e.copy()
    ws.mask[1], e[:, 1], y[:, 1] = 0.0, 1e12 * e[:, 1], 1e12 * y[:, 1]
    diagnose._set_weights(ws, e, y)
    assert ws.weights[1] == 0.0 and np.array_equal(np.delete(ws.weights, 1), np.delete(weights, 1))


@pytest.mark.parametrize("yaw", [1e-4, 1e-6])
def test_a_term_its_own_dof_equation_measures_is_excited_for_the_loop_as_for_least_squares(yaw):
    """A surge run whose yaw rate is ``yaw`` of its speed: N:r*abs(r) is ~yaw² of X:u*abs(u).
    The loop's refit judged excitation over the six DOF equations at once: at 1e-4 the column,
    1e-8 of the surge one, read "not excited (zero regressor)", and at 1e-6 (1e-12) rounding
    beside the surge column; either way N:r*abs(r) = 0 and its s.e. NaN, where the yaw
    equation measures it and the least-squares trainer, judging each DOF equation apart and
    each column at its own floor, estimates it. The loop now judges as the trainer does."""
    import warnings

    from conftest import make_vehicle

    from nnid.datasets.arrays import log_arrays
    from nnid.loop.diagnose import Workspace, refit
    from nnid.models.parametric import ParametricFossen
    from nnid.physics.parts import Parts
    from nnid.trainers.least_squares import LeastSquares

    truth = {"X:u*abs(u)": -30.0, "N:r*abs(r)": -5.0}
    vehicle = make_vehicle(damping={"model": None, "coefficients": truth})
    rng = np.random.default_rng(0)

    def run(name: str, phase: float) -> pd.DataFrame:
        t = np.arange(2000) * 0.05
        zero = np.zeros(t.size)
        log = pd.DataFrame({"t": t, "experiment": name, "x": zero, "y": zero, "z": zero,
                            "phi": zero, "theta": zero, "psi": zero, "v": zero, "w": zero,
                            "p": zero, "q": zero, "dv": zero, "dw": zero, "dp": zero, "dq": zero,
                            "u": 1.0 + 0.5 * np.sin(0.3 * t + phase),
                            "du": 0.15 * np.cos(0.3 * t + phase),
                            "r": yaw * np.sin(0.7 * t + phase),
                            "dr": 0.7 * yaw * np.cos(0.7 * t + phase)})  # fmt: skip
        # the forces that fly this motion under the true file, with noise in X and N
        data = log_arrays(log.assign(**{f"tau_{f}": 0.0 for f in "XYZKMN"}), vehicle)
        force = ParametricFossen(vehicle, []).equation_residual(Parts.from_vehicle(vehicle), data)
        force[:, 0] += rng.normal(0, 1e-9, t.size)
        force[:, 5] += rng.normal(0, 1e-13, t.size)
        return log.assign(**{f"tau_{f}": force[:, k] for k, f in enumerate("XYZKMN")})

    train = run("a", 0.0)
    ws = Workspace(train, run("b", 1.0), vehicle, None, zoh_midpoint=False, dofs=("u", "r"))
    trained = LeastSquares(correlated=False).solve(
        ParametricFossen(vehicle, list(truth), ["u", "r"]).regression(log_arrays(train, vehicle))
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fit = refit(ws, vehicle, list(truth), held_out=False)
    assert trained.excitation.unexcited == [] and trained.excitation.collinear == []
    for k, value in enumerate(truth.values()):
        assert 0 < fit.stderr[k] < abs(value) / 100, (fit.theta, fit.stderr)
        assert fit.theta[k] == pytest.approx(value, abs=4 * fit.stderr[k])
        assert trained.theta[k] == pytest.approx(fit.theta[k], abs=fit.stderr[k] / 10)


def test_an_effect_that_differs_run_to_run_has_an_s_e_that_says_so():
    """Ballast that differs from run to run (W − B of 2 to 6 N over eight runs): the residual's
    correlation time gave the added buoyancy offset a s.e. of a few hundredths of a newton,
    while holding out other runs moved it by newtons; the run-clustered s.e. reads the spread
    across the training runs."""
    veh = load_vehicle(MINIROV)
    offsets = [2.0, 6.0, 3.0, 5.0, 2.5, 5.5, 4.0, 4.5]
    log = pd.concat(
        [effect_log(veh, [("buoyancy_offset", b)], duration=60, n_experiments=1, seed=k,
                    measurement=DVL).assign(experiment=f"run{k}")
         for k, b in enumerate(offsets)],
        ignore_index=True,
    )  # fmt: skip
    fitted = ResidualLoop(veh, max_effects=1).fit(log)
    result = fitted.as_dict()
    added = result["steps"][0]["added"]
    assert added["effect"] == "buoyancy_offset"
    train = [p["experiment"] for p in result["settings"]["split"]["parts"]["train"]]
    spread = np.std([offsets[int(r[3:])] for r in train], ddof=1) / np.sqrt(len(train))
    assert 0.5 * spread < added["stderr"]["value"] < 3 * spread, (added, spread)


def test_an_added_effect_the_log_cannot_tell_from_another_says_so():
    from nnid.reports.loop_report import effect_sentence

    added = {
        "effect": "coupled_damping.Z:w*Vw",
        "meaning": "heave damping growing with the speed through the water",
        "params": {"value": -31.0},
        "stderr": {"value": 2.0},
        "same_column_as": ["coupled_damping.Z:abs(w)*V"],
    }
    sentence = effect_sentence(added)
    assert sentence.endswith(
        "(on this log coupled_damping.Z:w*Vw is the same column as coupled_damping.Z:abs(w)*V: "
        "the data cannot tell them apart)"
    )
    assert "cannot tell" not in effect_sentence({**added, "same_column_as": []})


def test_a_loop_whose_baseline_cannot_be_simulated_says_nothing_was_judged(tmp_path):
    """A vehicle file with a positive Z_wdot and K_pdot: every candidate the tests passed
    (added_mass.w removes 72 % of the held-out force residual) met a baseline whose held-out
    simulation diverges one step ahead, and the loop said "No significant effect"; it now
    says none could be judged, and loop.json keeps the vehicle file's warnings."""
    from typer.testing import CliRunner

    from nnid.cli import app

    text = resources.files("nnid.demo_data").joinpath("minirov.toml").read_text()
    bad = text.replace("Z_wdot = -18.7", "Z_wdot = 13.2").replace("K_pdot = -0.19", "K_pdot = 0.25")
    assert bad != text
    (tmp_path / "bad.toml").write_text(bad)
    data = str(resources.files("nnid.demo_data").joinpath("demo_minirov_heave.parquet"))
    out = tmp_path / "out"
    args = ["loop", "--data", data, "--vehicle", str(tmp_path / "bad.toml"), "--out", str(out)]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    assert "No effect was added, and none could be judged" in res.output
    assert "No significant effect" not in res.output
    result = json.loads((out / "loop.json").read_text())
    assert result["added"] == []
    # nothing added: "after" is the baseline's, fitted on the training part alone
    assert result["validation_used_for"] is None
    assert any("Z_wdot = 13.2 > 0" in w for w in result["warnings"]), result["warnings"]
    # a refusal after loading writes no loop.json: the warnings are said all the same
    res = CliRunner().invoke(app, [*args[:-1], str(tmp_path / "o2"), "--validation", "nosuch"])
    assert res.exit_code == 2 and "Z_wdot = 13.2 > 0" in res.output, res.output


def test_the_total_line_says_a_diverged_one_step_score():
    """Where every horizon diverged, the one-step fallback too, the total line read "- before,
    - after": the mark of an error that was not measured. It says which it was."""
    from nnid.reports.loop_report import summary

    def errors(gone):
        none = {"w": None, "total": None}
        return {"free_run_nrmse": none, "diverged": {"w": 2.0},
                "k_step_nrmse": none, "k_step_diverged": {"w": 2.5},
                "one_step_nrmse": none, "one_step_diverged": gone}  # fmt: skip

    effect = "thruster_installation.w.neg"
    added = {"effect": effect, "params": {"value": 0.57}, "stderr": {"value": 0.02},
             "meaning": "heave thrust", "reason": "added"}  # fmt: skip
    result = {"settings": {"k_step_s": 1.0}, "before": errors({"w": 3.0}), "after": errors({}),
              "added": [effect], "steps": [{"added": added, "top": [added], "gate": "one step"}],
              "unexplained": {}}  # fmt: skip
    lines = summary(result)
    assert lines[-1] == (
        f"Total held-out one-step NRMSE: diverged before, not scored after ({effect} added)."
    )
    # the held-out runs chose what was added: said after the effect's sentence
    assert lines[0].startswith("Upward heave thrust") and "not an independent test" in lines[1]
    # nothing added: the baseline's one-step score is said the same way
    result.update(added=[], steps=[{"added": None, "top": [], "gate": "one step"}])
    (line, _) = summary(result)
    assert "(held-out one-step NRMSE diverged; the baseline's held-out free run" in line


def test_the_relative_force_error_has_one_yardstick_before_and_after():
    """The total force residual is each DOF's RMS over the RMS of its input force. After an
    added deadband that yardstick was the force past the deadband, smaller than the one
    'before' was divided by: the after total read 0.197 where the same yardstick gives 0.133.
    Both are measured against the force the vehicle file gives."""
    from nnid.physics.dofs import DOFS

    veh = load_vehicle("seamor")
    log = effect_log(
        veh, [("thruster_deadband", 3.0)], duration=300, dt=0.05, seed=11, measurement=DVL
    )
    loop = ResidualLoop(veh, max_effects=1).fit(log)
    assert loop.added == ["thruster_deadband"]
    tau = loop.workspace_.arrays(veh, "val")["tau"]
    for errors in (loop.before_, loop.after_):
        force = errors["force_rmse"]
        ratios = [
            force[d] / np.sqrt(np.mean(tau[:, i] ** 2))
            for i, d in enumerate(DOFS)
            if d in loop.dofs_ and np.any(tau[:, i])
        ]
        assert force["total"] == pytest.approx(np.mean(ratios), rel=1e-9)


def test_force_rmse_takes_a_dofs_residual_and_force_over_the_same_rows():
    """The force residual's RMS was taken over its finite rows, the input force's over all:
    a residual missing over a stretch of small force read as a ratio of 0.14 where the
    residual is a tenth of the force on every row it has. Both now over the same rows."""
    from nnid.loop.diagnose import force_rmse

    tau = np.zeros((200, 6))
    tau[:, 0] = np.r_[np.full(100, 10.0), np.full(100, 1.0)]
    r = 0.1 * tau
    r[100:] = np.nan
    out = force_rmse(r, tau, ("u", "r"))
    assert out["u"] == pytest.approx(1.0) and out["total"] == pytest.approx(0.1)
    assert out["r"] == 0.0  # no input in yaw: its residual is said, not in the total
    # a force only where the residual is missing: no ratio (it divided by 0)
    tau[:, 1] = np.r_[np.zeros(100), np.full(100, 3.0)]
    r[:100, 1] = 0.5
    out = force_rmse(r, tau, ("u", "v"))
    assert out["v"] == pytest.approx(0.5) and out["total"] == pytest.approx(0.1)


@pytest.mark.parametrize(
    ("settings", "field", "says"),
    [
        # a loop config's 'validation' names held-out runs; the share is validation_fraction
        ("validation_fraction = 0.999\nwarmup_s = 0.5", "validation_fraction", "less than 0.999"),
        ("validation_fraction = 0.01", "warmup_s", "hold out more than 0.01 (validation_fraction)"),
        ("filter_lambda = 1e-9", "filter_lambda", "give filter_lambda above"),
    ],
)
def test_cli_loop_config_settings_are_named_as_the_config_names_them(
    tmp_path, settings, field, says
):
    """A held-out share too large for the training part was said as field 'validation' (in a
    loop config, the list of held-out runs) and one too small for a scored second named only
    the warm-up; a filter too slow was blamed on the log, not on the config that set it."""
    from typer.testing import CliRunner

    from nnid.cli import app

    data = str(resources.files("nnid.demo_data").joinpath("demo_minirov_heave.parquet"))
    vehicle = str(resources.files("nnid.demo_data").joinpath("minirov.toml"))
    config = tmp_path / "loop.toml"
    config.write_text(f'kind = "loop"\n{settings}\n')
    args = ["loop", str(config), "--data", data, "--vehicle", vehicle, "--out"]
    res = CliRunner().invoke(app, [*args, str(tmp_path / "o")])
    assert res.exit_code == 2, res.output
    assert f"{config}, field '{field}'" in res.output, res.output
    assert says in res.output, res.output


@pytest.mark.parametrize("reach", [0.05, None])
def test_a_searched_size_at_the_edge_of_its_range_is_a_bound_not_a_measurement(monkeypatch, reach):
    """A 0.15 m/s current searched only up to 0.05 m/s (a vehicle holding station in it moves
    slowly, and the current's range is twice the fastest speed logged): the loop added it as
    0.050 ± 0.002 m/s, a confident size 50 standard errors from the truth. At the edge of
    the range the size is said to be a bound, with no standard error; within it nothing
    changes."""
    import nnid.loop.effects as effects
    from nnid.reports.loop_report import effect_sentence

    if reach is not None:
        monkeypatch.setattr(effects, "MAX_CURRENT", reach)
    veh = load_vehicle(MINIROV)
    meas = Measurement(kind="dvl_imu", velocity_noise=0.005)
    log = effect_log(
        veh, [("current.y", 0.15)], duration=300, dt=0.05, speed=0.4, seed=11, measurement=meas
    )
    loop = ResidualLoop(veh, max_effects=1).fit(log)
    assert loop.added == ["current.y"]
    added = loop.as_dict()["steps"][0]["added"]
    said = [w for w in loop.warnings_ if "lies at" in w]
    if reach is None:  # found within its range, measured
        assert added["edge"] is None and not said
        se = added["stderr"]["value"]
        assert added["params"]["value"] == pytest.approx(0.15, abs=3 * se)
        # bounded apart from the fit: 6000 samples know the current better than one sample's
        # velocity noise (0.005 m/s) does: the window is within it (a thirtieth of the current)
        assert 3 * se < meas.velocity_noise, se
        return
    assert added["params"]["value"] == pytest.approx(reach, rel=0.01)
    assert added["edge"].startswith("the upper edge of the range searched")
    assert added["stderr"]["value"] is None and added["percentile_error"] is None
    assert len(said) == 1 and said[0].startswith("current.y = 0.04996 lies at the upper edge")
    assert "the true size may lie beyond it, and is not measured" in effect_sentence(added)


def test_a_damping_candidate_with_the_sign_of_a_thrust_is_not_physical():
    """On a 4 N buoyancy offset, linear_damping.w = +31 passed every test ("passes the
    tests; ranked below the one added"): a diagonal damping that pushes the vehicle along its
    own speed gains energy, and only the ranking kept it out of the model."""
    from nnid.loop.residual_loop import thrust_signed

    veh = load_vehicle("seamor")
    meas = Measurement(kind="dvl_imu", velocity_noise=0.005)
    log = effect_log(
        veh, [("buoyancy_offset", 4.0)], duration=300, dt=0.05, speed=0.4, seed=11,
        measurement=meas,
    )  # fmt: skip
    loop = ResidualLoop(veh, max_effects=1).fit(log)
    assert loop.added == ["buoyancy_offset"]
    signed = [s for s in loop.steps_[0].ranked if thrust_signed(s.candidate.parameter, s.value)]
    assert signed, "no thrust-signed damping candidate on this log: the test tests nothing"
    assert not [s.name for s in signed if s.admissible]
    assert [s.name for s in signed if s.reason.startswith("not physical")]


def test_a_vehicle_file_with_no_coefficient_to_refit_gets_its_baseline():
    """A vehicle file with mass, inertia and restoring but no added mass or damping (nothing
    for the baseline to refit, p = 0 columns) crashed the held-out residual with "cannot
    reshape array of size 0" instead of scoring the file as it is."""
    from nnid.datasets.readers import load_log

    root = resources.files("nnid.demo_data")
    log, _ = load_log(str(root.joinpath("demo_minirov_heave.parquet")))
    data = load_vehicle(MINIROV).model_dump()
    data["added_mass"], data["damping"]["coefficients"] = {}, {}
    bare = type(load_vehicle(MINIROV)).model_validate(data)
    result = ResidualLoop(bare, max_effects=0).fit(log[log["experiment"].isin(["run0", "run1"])])
    before = result.as_dict()["before"]
    assert result.as_dict()["added"] == []
    assert before["k_step_nrmse"]["total"] is not None and before["k_step_nrmse"]["total"] > 0


def test_runs_joined_without_a_fresh_index_are_refused_before_the_loop():
    """Two runs joined by pd.concat keep their labels twice; the loop's preparation and
    split found a run's rows by label. One clear error saying the fix, before any fit."""
    from nnid.errors import NnidInputError

    veh = load_vehicle(MINIROV)
    t = np.arange(100) * 0.1
    forces = {f"tau_{f}": np.sin(t) for f in ("X", "Y", "Z", "K", "M", "N")}
    run = pd.DataFrame({"t": t, "u": 0.1 * np.sin(t), "w": 0.0, "r": 0.0, **forces})
    twice = pd.concat([run.assign(experiment="a"), run.assign(experiment="b")])
    with pytest.raises(NnidInputError, match=r"repeats 100 labels \(the first: 0\).*pd\.concat"):
        ResidualLoop(veh, max_effects=1).fit(twice)


def _flown(vehicle, name: str, motion: dict, noise: float, rng) -> pd.DataFrame:
    """A 100-s run of ``motion`` (velocity and acceleration columns; the rest zero) with the
    forces that fly it under ``vehicle``, and ``noise`` (N) of noise in X and Z."""
    from nnid.datasets.arrays import log_arrays
    from nnid.models.parametric import ParametricFossen
    from nnid.physics.parts import Parts

    t = np.arange(2000) * 0.05
    still = dict.fromkeys(["x", "y", "z", "phi", "theta", "psi", "u", "v", "w", "p", "q", "r",
                           "du", "dv", "dw", "dp", "dq", "dr"], np.zeros(t.size))  # fmt: skip
    log = pd.DataFrame(
        {"t": t, "experiment": name, **still, **{k: f(t) for k, f in motion.items()}}
    )
    data = log_arrays(log.assign(**{f"tau_{f}": 0.0 for f in "XYZKMN"}), vehicle)
    force = ParametricFossen(vehicle, []).equation_residual(Parts.from_vehicle(vehicle), data)
    force[:, [0, 2]] += rng.normal(0, noise, (t.size, 2))
    return log.assign(**{f"tau_{f}": force[:, k] for k, f in enumerate("XYZKMN")})


def _excitation_said(fit_call) -> list[str]:
    """The parameters a refit's warnings call not excited."""
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fit_call()
    said = [str(w.message) for w in caught if "not excited" in str(w.message)]
    return [n.strip() for m in said for n in m.split("zero regressor):")[1].split(",")]


@pytest.mark.parametrize("surge", [1e-7, 1e-13])
def test_a_candidate_the_data_do_not_excite_is_screened_as_not_excited(surge):
    """A heave run whose surge speed is ``surge`` of its heave, analysed in heave: the refit of
    the baseline with Z:u (or Z:u|u|) leaves it out as not excited (at 1e-7 nothing beside
    Z:w|w| in the heave equation, at 1e-13 rounding), but the closed-form screen scored it as
    if it were measured: a value, a standard error, a p-value and the F-test's verdict. The
    screen now judges each linear candidate as the refit would and says it is not excited,
    with nothing measured; the candidates the heave measures are scored as before."""
    from conftest import make_vehicle

    from nnid.loop.diagnose import NOT_EXCITED, Workspace, refit, screen_linear
    from nnid.reports.loop_report import candidate_rows

    vehicle = make_vehicle(damping={"model": None, "coefficients": {"Z:w*abs(w)": -30.0}})
    rng = np.random.default_rng(1)
    runs = [
        _flown(vehicle, name, {"w": lambda t, a=a: 0.4 * np.sin(0.5 * t + a),
                               "dw": lambda t, a=a: 0.2 * np.cos(0.5 * t + a),
                               "u": lambda t, a=a: surge * np.cos(0.3 * t + a),
                               "du": lambda t, a=a: -0.3 * surge * np.sin(0.3 * t + a)},
               1e-3, rng)
        for name, a in (("a", 0.0), ("b", 1.0))
    ]  # fmt: skip
    ws = Workspace(*runs, vehicle, None, zoh_midpoint=False, dofs=("w",))
    fit = refit(ws, vehicle, ["Z:w*abs(w)"])
    names = ["coupled_damping.Z:u", "coupled_damping.Z:u*abs(u)", "linear_damping.w",
             "coupled_damping.Z:w*w", "external_bias.w", "added_mass.w"]  # fmt: skip
    chosen = [c for c in candidates(vehicle, runs[0]) if c.name in names]
    assert sorted(c.name for c in chosen) == sorted(names)
    scored = {s.name: s for s in screen_linear(ws, fit, chosen)}
    assert set(scored) == set(names)
    unexcited = {  # as the refit of the baseline with each candidate says
        c.name: c.parameter
        in _excitation_said(lambda c=c: refit(ws, vehicle, [*fit.unknowns, c.parameter], False))
        for c in chosen
    }
    assert unexcited == {c.name: "u" in c.parameter for c in chosen}
    assert {n: s.reason == NOT_EXCITED for n, s in scored.items()} == unexcited
    for name, s in scored.items():
        if unexcited[name]:
            assert not s.excited and not s.admissible and np.isnan(s.value) and np.isnan(s.p_value)
            _, value, se, _, p, gain, verdict = candidate_rows([s.as_dict()])[0]
            assert value == se == p == gain == "-" and verdict == NOT_EXCITED
        else:
            assert s.excited and np.isfinite(s.value) and np.isfinite(s.p_value)


def test_a_heave_only_fit_judges_its_columns_by_the_heave_equation_as_least_squares_does():
    """A surge run whose heave is 1e-12 of it, analysed in heave alone. Z_wdot's column is ẇ
    in the heave equation and C_A(ν)ν products in the other five; its rounding floor was sized
    over all six (a product's, 1e-20 of the motion squared, not ẇ's 1e-10 of the acceleration),
    and the loop's refit estimated Z_wdot off a heave of rounding, beside Z:w|w| it called
    rounding in the same equation, where the least-squares trainer of the heave equation calls
    both not excited. The floors are now sized over the equations the loop fits, and its screen
    says added_mass.w not excited too."""
    from conftest import make_vehicle

    from nnid.datasets.arrays import log_arrays
    from nnid.loop.diagnose import NOT_EXCITED, Workspace, refit, screen_linear
    from nnid.models.parametric import ParametricFossen
    from nnid.trainers.least_squares import LeastSquares

    truth = {"X:u*abs(u)": -30.0, "Z:w*abs(w)": -30.0}
    vehicle = make_vehicle(damping={"model": None, "coefficients": truth})
    rng = np.random.default_rng(0)
    heave = 1e-12
    runs = [
        _flown(vehicle, name, {"u": lambda t, a=a: 1.0 + 0.5 * np.sin(0.3 * t + a),
                               "du": lambda t, a=a: 0.15 * np.cos(0.3 * t + a),
                               "w": lambda t, a=a: heave * np.sin(0.7 * t + a),
                               "dw": lambda t, a=a: 0.7 * heave * np.cos(0.7 * t + a)},
               1e-3, rng)
        for name, a in (("a", 0.0), ("b", 1.0))
    ]  # fmt: skip
    names = ["Z:w*abs(w)", "Z_wdot"]
    trained = LeastSquares(correlated=False)
    trainer_said = _excitation_said(
        lambda: trained.solve(
            ParametricFossen(vehicle, names, ["w"]).regression(log_arrays(runs[0], vehicle))
        )
    )
    assert sorted(trainer_said) == sorted(names)
    ws = Workspace(*runs, vehicle, None, zoh_midpoint=False, dofs=("w",))
    assert sorted(_excitation_said(lambda: refit(ws, vehicle, names, held_out=False))) == sorted(
        trainer_said
    )
    fit = refit(ws, vehicle, names[:1])
    added_mass = [c for c in candidates(vehicle, runs[0]) if c.name == "added_mass.w"]
    assert screen_linear(ws, fit, added_mass)[0].reason == NOT_EXCITED


def test_candidates_the_data_do_not_excite_are_counted_in_one_line_and_named_in_loop_json():
    """A heave run whose surge is rounding (1e-13 of the heave), analysed in heave: the terms
    in u are not excited and measure nothing. Listed in the pass's table and in loop.json's
    ranked candidates they padded both with rows of "not excited" (165 on a BlueROV1 log
    without u or v); they are now named in the step's ``not_excited`` and counted in one line
    of the report, and every row of the tables is a scored candidate."""
    from conftest import make_vehicle

    from nnid.loop.diagnose import NOT_EXCITED
    from nnid.reports.loop_report import markdown

    vehicle = make_vehicle(damping={"model": None, "coefficients": {"Z:w*abs(w)": -30.0}})
    rng = np.random.default_rng(2)
    log = pd.concat(
        [
            _flown(vehicle, name, {"w": lambda t, a=a: 0.4 * np.sin(0.5 * t + a),
                                   "dw": lambda t, a=a: 0.2 * np.cos(0.5 * t + a),
                                   "u": lambda t, a=a: 1e-13 * np.cos(0.3 * t + a),
                                   "du": lambda t, a=a: -3e-14 * np.sin(0.3 * t + a)},
                   1e-3, rng)
            for name, a in (("a", 0.0), ("b", 1.0), ("c", 2.0))
        ],
        ignore_index=True,
    )  # fmt: skip
    loop = ResidualLoop(vehicle, dofs=("w",), max_effects=1).fit(log)
    result = loop.as_dict()
    step = result["steps"][0]
    named = step["not_excited"]
    # the damping terms in a velocity other than w (u of rounding, v p q r zero), and only those
    ranked = loop.steps_[0].ranked
    in_others = {
        s.name
        for s in ranked
        if ":" in (s.candidate.parameter or "")  # a damping term; a search has none
        and set(s.candidate.parameter.split(":")[1]) & set("uvpqr")
    }
    assert named and set(named) == in_others
    shown = [*result["candidates"], *(c for s in result["steps"] for c in s["top"])]
    assert shown and not {c["effect"] for c in shown} & set(named)
    assert all(c["reason"] != NOT_EXCITED and c["improvement"] is not None for c in shown)
    # tested: those scored (the Bonferroni family), not those named
    assert result["candidates_tested"] == loop.steps_[0].tested < len(ranked)
    assert result["candidates_not_excited"] == len(named)
    said = [line for line in markdown(result).splitlines() if "not excited" in line]
    assert said == [
        line for line in said if line.startswith(f"{len(named)} candidates not excited")
    ] and len(said) == len(result["steps"])


def _collinear_said(fit_call) -> list[str]:
    """The parameters a refit's warnings call collinear."""
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fit_call()
    said = [str(w.message) for w in caught if "collinear regressors" in str(w.message)]
    return [
        n.strip()
        for m in said
        for n in m.split("collinear regressors):")[1].split(";")[0].split(",")
    ]


def _heave_with_a_little_surge(vehicle, rng, names=("a", "b")) -> list[pd.DataFrame]:
    """Heave runs with a sway 2.5 % of the heave: Z's V is |w| but for the sway, so its w V is
    w|w| but for a column far below the refit's rank rule, yet not zero."""
    return [
        _flown(vehicle, name, {"w": lambda t, a=a: 0.4 * np.sin(0.5 * t + a),
                               "dw": lambda t, a=a: 0.2 * np.cos(0.5 * t + a),
                               "v": lambda t, a=a: 0.01 * np.cos(0.3 * t + a),
                               "dv": lambda t, a=a: -0.003 * np.sin(0.3 * t + a)},
               1e-3, rng)
        for name, a in zip(names, (0.0, 1.0, 2.0), strict=False)
    ]  # fmt: skip


def test_a_candidate_in_the_span_of_the_model_is_named_not_identifiable_not_scored():
    """Beside a fitted Z:w|w|, Z:w*V and Z:abs(w)*Vw of a heave run with little sway are w|w|
    but for a sliver: the refit with either calls the pair collinear, but the closed-form
    screen scored them (here p 0.66 and 0.43 for a coefficient of -30; ROMEO's heave: p 0.9,
    1.9e5 for -430). They are now named not identifiable, with nothing measured, as the refit's rank
    rule judges them; the candidates the refit separates are scored as before."""
    from conftest import make_vehicle

    from nnid.loop.diagnose import NOT_IDENTIFIABLE, Workspace, refit, screen_linear

    vehicle = make_vehicle(damping={"model": None, "coefficients": {"Z:w*abs(w)": -30.0}})
    runs = _heave_with_a_little_surge(vehicle, np.random.default_rng(3))
    ws = Workspace(*runs, vehicle, None, zoh_midpoint=False, dofs=("w",))
    fit = refit(ws, vehicle, ["Z:w*abs(w)"])
    names = ["coupled_damping.Z:w*V", "coupled_damping.Z:abs(w)*Vw", "linear_damping.w",
             "coupled_damping.Z:w*w", "external_bias.w"]  # fmt: skip
    chosen = [c for c in candidates(vehicle, runs[0]) if c.name in names]
    assert sorted(c.name for c in chosen) == sorted(names)
    scored = {s.name: s for s in screen_linear(ws, fit, chosen)}
    collinear = {  # as the refit of the baseline with each candidate says
        c.name: c.parameter
        in _collinear_said(lambda c=c: refit(ws, vehicle, [*fit.unknowns, c.parameter], False))
        for c in chosen
    }
    assert collinear == {n: n.startswith(("coupled_damping.Z:w*V", "coupled_damping.Z:abs(w)*V"))
                         for n in names}  # fmt: skip
    assert set(scored) == set(names)
    for name, s in scored.items():
        assert s.excited
        if collinear[name]:
            assert not s.identifiable and not s.scored and s.reason == NOT_IDENTIFIABLE
            assert np.isnan(s.value) and np.isnan(s.p_value) and np.isnan(s.improvement)
        else:
            assert s.scored and np.isfinite(s.value) and np.isfinite(s.p_value)


def test_identifiable_judges_all_candidates_in_one_decomposition_by_the_rank_rule(monkeypatch):
    """identifiable is the refit's rank rule (excitation_from_gram) on each candidate's
    augmented Gram matrix. Called once a candidate (a Python call of the report and an
    eigen-decomposition each, hundreds a pass) it was 4 % of the demo's loop; the candidates
    are now decomposed in one call (one a set of zero columns), each with the verdict the rule
    gives it alone: in the span, at 1e-5 of it (below the rule's tolerance), zero, a scaled
    copy of a column, and those that add a direction."""
    from nnid.evaluation.persistence import excitation_from_gram
    from nnid.loop.diagnose import identifiable

    rng = np.random.default_rng(0)
    x = rng.normal(size=(200, 3))
    phi = np.column_stack([x[:, 0], x[:, 1], 1e3 * x[:, 2]])
    free = rng.normal(size=200)
    cols = np.column_stack([
        x[:, 0] + x[:, 1], x[:, 0] - 2e3 * x[:, 2] + 1e-5 * free, 1e8 * x[:, 1], np.zeros(200),
        free, x[:, 0] + 1e-2 * free, x[:, 0] * x[:, 1],
    ])  # fmt: skip
    a_mat, b, q = phi.T @ phi, phi.T @ cols, np.sum(cols**2, 0)

    def rank(gram: np.ndarray) -> int:
        m = gram.shape[0]
        return excitation_from_gram(gram, 200, [str(j) for j in range(m)],
                                    column_rms=np.ones(m), reference=1.0).rank  # fmt: skip

    one_at_a_time = [
        rank(np.block([[a_mat, b[:, [k]]], [b[:, [k]].T, q[[k], None]]])) > rank(a_mat)
        for k in range(q.size)
    ]
    assert one_at_a_time == [False, False, False, False, True, True, True]
    calls = []
    eigh = np.linalg.eigh
    monkeypatch.setattr(np.linalg, "eigh", lambda a: calls.append(a.shape) or eigh(a))
    assert identifiable(a_mat, b, q, 200).tolist() == one_at_a_time
    # the fit's own matrix, the candidates', and those of the zero column (its own set)
    assert len(calls) == 3


def test_the_bonferroni_correction_counts_only_the_candidates_scored():
    """A candidate not excited (terms in a surge of zero) or not identifiable beside the
    model (Z:w*V beside Z:w|w|) has no p-value: it was not tested. The correction divided α by
    every candidate of the pool (BlueROV1: 324, of which 165 were zero columns), a threshold
    stricter than the family tested asks; it now divides by those tested, which loop.json
    counts apart from those named."""
    from conftest import make_vehicle

    from nnid.reports.loop_report import markdown

    vehicle = make_vehicle(damping={"model": None, "coefficients": {"Z:w*abs(w)": -30.0}})
    log = pd.concat(_heave_with_a_little_surge(vehicle, np.random.default_rng(4), "abc"),
                    ignore_index=True)  # fmt: skip
    loop = ResidualLoop(vehicle, dofs=("w",), max_effects=1, nonlinear=False).fit(log)
    result = loop.as_dict()
    step = loop.steps_[0]
    unscored = [s for s in step.ranked if not s.scored]
    assert result["steps"][0]["not_identifiable"]
    # every linear candidate of the pool is ranked: scored or named
    pool = [c for c in candidates(vehicle, loop.workspace_.train) if "w" in c.dofs and c.linear]
    assert len(step.ranked) == len(pool)
    assert result["candidates_tested"] == len(pool) - len(unscored)
    assert result["candidates_not_excited"] + result["candidates_not_identifiable"] == len(unscored)
    threshold = f"{0.01 / result['candidates_tested']:.2g}"
    said = [s.reason for s in step.ranked if s.reason.startswith("not significant")]
    assert said and all(r.endswith(f"≥ {threshold})") for r in said)
    assert f"over the {result['candidates_tested']} candidates tested" in markdown(result)


def test_the_report_states_each_passs_own_bonferroni_count():
    """Each pass is judged at α over the candidates it tested (steps[k].tested), and a later
    pass tests fewer (an added effect leaves the pool): the report said the first pass's count
    for every pass. Each pass's own now; one count where they agree; the first pass's where
    a file has no per-pass count."""
    from nnid.reports.loop_report import _tested_text

    two = {"candidates_tested": 160, "steps": [{"tested": 160}, {"tested": 158}]}
    assert "160 in pass 1, 158 in pass 2" in _tested_text(two)
    same = {"candidates_tested": 160, "steps": [{"tested": 160}, {"tested": 160}]}
    assert "over the 160 candidates tested in each pass" in _tested_text(same)
    older = {"candidates_tested": 324, "steps": [{}, {}]}
    assert "over the 324 candidates tested in the first pass" in _tested_text(older)
    assert _tested_text({"candidates_tested": 5, "steps": []}) == ""


def test_a_linear_candidate_not_finite_on_the_fits_rows_is_named_not_dropped():
    """The closed-form screen dropped a candidate whose column is NaN on a row the fit reads
    (its sums are NaN: nothing to judge it by): neither scored nor named, loop.json and the
    report never said it was looked at. It now comes back named not finite, with nothing
    measured; a finite column in the span of the fit's (the screen's denominator ~0) is named
    not identifiable, and a column that adds a direction is scored as before."""
    from types import SimpleNamespace

    from nnid.loop.diagnose import NOT_FINITE, NOT_IDENTIFIABLE, Fit, screen

    rng = np.random.default_rng(0)
    n = 200
    x, z, other = rng.normal(size=(3, n))
    phi = np.zeros((n, 6, 1))
    phi[:, 2, 0] = x
    e = np.zeros((n, 6))
    e[:, 2] = 0.5 * z + 0.01 * rng.normal(size=n)
    fit = Fit(
        None, ["Z:w"], np.array([1.0]), np.array([0.1]), phi, phi, e, e, float(e[:, 2] @ e[:, 2])
    )
    ws = SimpleNamespace(weights=np.eye(6)[2], dofs=("w",), tau_corr=1.0)
    cols = np.zeros((n, 6, 3))
    cols[:, 2, 0] = -z  # adds a direction: explains the residual
    cols[:, 2, 1] = 3.0 * x  # in the span of the fit's column
    cols[:, 2, 2] = other
    cols[7, 2, 2] = np.nan  # one row the fit reads
    cands = [Candidate(f"c{k}", "linear_damping", f"Z:c{k}") for k in range(3)]
    out = {s.name: s for s in screen(ws, fit, cands, cols, cols)}
    assert set(out) == {"c0", "c1", "c2"}
    good, span, bad = out["c0"], out["c1"], out["c2"]
    assert good.scored and good.p_value < 1e-6 and good.value == pytest.approx(0.5, rel=0.05)
    assert span.finite and not span.identifiable and span.reason == NOT_IDENTIFIABLE
    assert not bad.finite and not bad.scored and bad.reason == NOT_FINITE
    assert bad.excited and bad.identifiable  # counted once, as not finite only
    assert np.isnan([bad.value, bad.stderr, bad.p_value, bad.improvement]).all()


def test_a_search_with_nothing_to_search_is_named_not_counted_as_tested(monkeypatch):
    """A 1-D search whose linearised column is not finite on the fit's rows had an empty
    pre-screen: it returned None, read as "searched, found no better fit", and was counted in
    the Bonferroni family (loop.json's tested, the report's count) though nothing was tested.
    It is now named in the step's ``not_finite`` (and counted in ``candidates_not_finite``),
    and tested counts the candidates scored alone, in loop.json and the report alike."""
    from conftest import make_vehicle

    import nnid.loop.diagnose as diagnose
    from nnid.loop.diagnose import NOT_FINITE
    from nnid.reports.loop_report import _tested_text, markdown

    sensitivity = diagnose.sensitivity
    monkeypatch.setattr(  # every searched effect's linearised column NaN
        diagnose, "sensitivity", lambda *a: [np.full_like(c, np.nan) for c in sensitivity(*a)]
    )
    vehicle = make_vehicle(damping={"model": None, "coefficients": {"Z:w*abs(w)": -30.0}})
    log = pd.concat(_heave_with_a_little_surge(vehicle, np.random.default_rng(4), "abc"),
                    ignore_index=True)  # fmt: skip
    loop = ResidualLoop(vehicle, dofs=("w",), max_effects=1).fit(log)
    result = loop.as_dict()
    ranked = loop.steps_[0].ranked
    searched = {s.name: s for s in ranked if not s.candidate.linear}
    assert searched and all(s.reason == NOT_FINITE and not s.scored for s in searched.values())
    step = result["steps"][0]
    assert sorted(step["not_finite"]) == sorted(searched)
    assert result["candidates_not_finite"] == len(searched)
    tested = sum(s.scored for s in ranked)
    assert result["candidates_tested"] == step["tested"] == tested
    assert f" over the {tested} candidates tested" in _tested_text(result)
    said = [line for line in markdown(result).splitlines() if "not finite" in line]
    assert len(said) == 1 and said[0].startswith(f"{len(searched)} candidate")


def test_a_search_that_found_no_better_fit_is_named_in_loop_json_and_the_report(monkeypatch):
    """A 1-D search that ran and found no better fit than the model's is counted among the
    candidates tested (the Bonferroni count) but has no row to rank: loop.json and the report
    named it nowhere, so a reader could not see what the count held. Each step's
    ``no_better_fit`` now names it, and the report says it in one line. Here every search's
    optimum is where it started (the stand-in optimiser returns the current value, 0)."""
    import html

    from conftest import make_vehicle
    from scipy.optimize import OptimizeResult

    import nnid.loop.diagnose as diagnose
    from nnid.reports.loop_report import html_page, markdown

    monkeypatch.setattr(
        diagnose, "minimize_scalar", lambda *a, **k: OptimizeResult(x=0.0, success=True, nfev=1)
    )
    damping = {"model": None, "coefficients": {"Z:w*abs(w)": -30.0}}
    truth = make_vehicle(damping=damping, current=[0.0, 0.0, 0.1])
    log = pd.concat(_heave_with_a_little_surge(truth, np.random.default_rng(5), "abc"),
                    ignore_index=True)  # fmt: skip
    vehicle = make_vehicle(damping=damping)
    loop = ResidualLoop(vehicle, dofs=("w",), max_effects=1).fit(log)
    result, step = loop.as_dict(), loop.steps_[0]
    ranked = {s.name for s in step.ranked}
    searches = [c.name for c in candidates(vehicle, loop.workspace_.train) if not c.linear]
    found_nothing = [n for n in searches if n not in ranked]
    # the current's pre-screen is significant, so it was searched, and found nothing better
    assert "current.z" in found_nothing
    assert result["steps"][0]["no_better_fit"] == found_nothing
    assert result["candidates_no_better_fit"] == len(found_nothing)
    assert step.tested == sum(s.scored for s in step.ranked) + len(found_nothing)
    line = f"{len(found_nothing)} 1-D search"
    said = [ln for ln in markdown(result).splitlines() if ln.startswith(line)]
    assert len(said) == 1 and "current.z" in said[0] and "steps[0].no_better_fit" in said[0]
    assert html.escape(said[0]) in html_page(result, {})


def _measured(s) -> tuple:
    """What the screen measured of a candidate, to compare two screens of it."""
    return (s.value, s.stderr, s.p_value, s.improvement, s.percentile_error, s.reason, s.scored)


def test_a_column_nan_only_in_an_equation_not_analysed_is_judged_like_any_other(monkeypatch):
    """A heave loop weights surge 0: no fit reads the X rows. A damping candidate whose column
    was NaN there (on one sample) had NaN weighted sums (0 · NaN = NaN) and was named not
    finite, with nothing measured, though every row the refit reads is finite; it fell out of
    SINDy's opinion too. It is now judged as the same column without the NaN (value, s.e.,
    p-value, held-out gain alike) and SINDy keeps it; NaN on a row the fit reads (heave) is
    still not finite."""
    from conftest import make_vehicle

    import nnid.loop.diagnose as diagnose
    from nnid.loop.diagnose import NOT_FINITE, Workspace, refit, screen_linear, sindy_opinion

    quadratic = {"Z:w*abs(w)": -30.0}
    truth = make_vehicle(damping={"model": None, "coefficients": {**quadratic, "Z:w": -20.0}})
    runs = _heave_with_a_little_surge(truth, np.random.default_rng(6))
    vehicle = make_vehicle(damping={"model": None, "coefficients": quadratic})
    ws = Workspace(*runs, vehicle, None, zoh_midpoint=False, dofs=("w",))
    fit = refit(ws, vehicle, ["Z:w*abs(w)"])
    assert ws.weights[0] == 0 and ws.weights[2] > 0
    chosen = [c for c in candidates(vehicle, runs[0])
              if c.name in ("linear_damping.w", "coupled_damping.Z:w*w")]  # fmt: skip
    assert len(chosen) == 2
    clean = {s.name: s for s in screen_linear(ws, fit, chosen)}
    opinion = sindy_opinion(ws, fit, list(clean.values()))
    assert "linear_damping.w" in opinion

    block = diagnose.damping_block

    def doctored(dof: int):
        def cols(*args):
            out = block(*args).copy()
            out[7, dof, :] = np.nan  # one sample, in surge (weight 0) or heave
            return out

        return cols

    monkeypatch.setattr(diagnose, "damping_block", doctored(0))
    unread = {s.name: s for s in screen_linear(ws, fit, chosen)}
    assert {n: _measured(s) for n, s in unread.items()} == {
        n: _measured(s) for n, s in clean.items()
    }
    assert all(s.scored and np.isfinite(s.value) for s in unread.values())
    assert sindy_opinion(ws, fit, list(unread.values())) == opinion
    monkeypatch.setattr(diagnose, "damping_block", doctored(2))
    read = screen_linear(ws, fit, chosen)
    assert all(s.reason == NOT_FINITE and not s.finite for s in read)


def _heave_fit_beside_a_current():
    """A heave-only fit of Z:w*abs(w) on runs of a vehicle in a 0.1 m/s vertical current its
    model lacks: (vehicle, workspace, fit)."""
    from conftest import make_vehicle

    from nnid.loop.diagnose import Workspace, refit

    damping = {"model": None, "coefficients": {"Z:w*abs(w)": -30.0}}
    truth = make_vehicle(damping=damping, current=[0.0, 0.0, 0.1])
    runs = _heave_with_a_little_surge(truth, np.random.default_rng(5))
    vehicle = make_vehicle(damping=damping)
    ws = Workspace(*runs, vehicle, None, zoh_midpoint=False, dofs=("w",))
    return vehicle, ws, refit(ws, vehicle, ["Z:w*abs(w)"])


def test_a_search_whose_range_leaves_no_linearised_step_keeps_its_better_fit(monkeypatch):
    """The s.e. of a 1-D search's optimum is read off the effect's column linearised over
    1e-3 of the range about it. A range narrower than the floats resolve beside its size
    (here three floats at 0.1) gives no such step, and the search came back None, "searched
    and found no better fit", though it had found and measured one (the true current, the
    residual gone). It now comes back with the refit's exact numbers and its s.e. said not
    measured. The vocabulary's ranges all hold 0 (a step is 1e-3 of at least the value):
    only a Candidate built with such a range gets here."""

    import nnid.loop.diagnose as diagnose
    from nnid.loop.diagnose import refit, search_nonlinear

    vehicle, ws, fit = _heave_fit_beside_a_current()
    lo = 0.1
    hi = np.nextafter(np.nextafter(lo, 1.0), 1.0)
    cand = Candidate("current.z", "current", bounds=(lo, float(hi)))
    sensitivity, steps = diagnose.sensitivity, []

    def resolved(ws, vehicle, cand, a, b):
        # the pre-screen's own step (0.02 of the range, from the current 0) the floats lose
        steps.append((a, b))
        return sensitivity(ws, vehicle, cand, a, a + 1e-3)

    monkeypatch.setattr(diagnose, "sensitivity", resolved)
    s = search_nonlinear(ws, fit, cand)
    assert s is not None and s.scored and lo <= s.value <= hi
    best = refit(ws, cand.augment(fit.vehicle, s.value), fit.unknowns)
    assert s.drss == fit.rss - best.rss > 0.99 * fit.rss
    assert s.p_value < 1e-6 and s.improvement > 0.99
    assert np.isnan(s.stderr) and np.isnan(s.percentile_error)
    assert s.as_dict()["stderr"]["value"] is None and s.as_dict()["percentile_error"] is None
    assert len(steps) == 1  # the pre-screen's: no s.e. read off a step rounded away
    # judged, it is no parameter shown significant, and said so: not "uncertain (nan % ...)"
    ResidualLoop(vehicle)._judge(s, 1, fit)
    assert s.reason == (
        f"parameter uncertainty not measured: {diagnose.NO_LINEARISED_STEP}; its significance "
        "cannot be shown"
    )


def test_a_search_whose_linearised_column_measures_nothing_says_why(monkeypatch):
    """A 1-D search's s.e. is read off its column linearised at the optimum, screened as any
    column: where that column is not excited (or not identifiable, not finite) no s.e. is
    measured, and the verdict said only 'parameter uncertainty not measured', the column's
    reason lost; at a value of 0 its percentile error is inf and the verdict read 'parameter
    uncertain (inf % > 51 %)', as if an uncertainty had been measured. Both now say that no
    s.e. was measured, and why."""

    import nnid.loop.diagnose as diagnose
    from nnid.loop.diagnose import NOT_EXCITED, search_nonlinear

    vehicle, ws, fit = _heave_fit_beside_a_current()
    cand = Candidate("current.z", "current", bounds=(-0.5, 0.5))
    sensitivity, calls = diagnose.sensitivity, []

    def flat_at_the_optimum(ws, vehicle, cand, a, b):
        # the pre-screen's column as it is; the one linearised at the optimum all zero
        calls.append((a, b))
        cols = sensitivity(ws, vehicle, cand, a, b)
        return cols if len(calls) == 1 else tuple(np.zeros_like(c) for c in cols)

    monkeypatch.setattr(diagnose, "sensitivity", flat_at_the_optimum)
    s = search_nonlinear(ws, fit, cand)
    assert s is not None and s.scored and len(calls) == 2
    assert s.value == pytest.approx(0.1, abs=0.01) and s.p_value < 1e-6
    assert np.isnan(s.stderr)
    excited = NOT_EXCITED.removesuffix(": nothing of it is measured")
    ResidualLoop(vehicle)._judge(s, 1, fit)
    assert s.reason.startswith("parameter uncertainty not measured: its column linearised at")
    assert excited in s.reason and s.reason.endswith("its significance cannot be shown")
    # the same at a value of 0, whose percentile error is inf, not NaN
    s.value, s.percentile_error, s.reason = 0.0, float("inf"), ""
    ResidualLoop(vehicle)._judge(s, 1, fit)
    assert s.reason.startswith("parameter uncertainty not measured: its column linearised at")


def test_a_search_at_the_edge_of_the_values_the_vehicle_takes_keeps_its_better_fit():
    """A vehicle file that declares a vertical current of 9.9 m/s, in a 10 m/s one: the search
    of current.z over ±0.5 finds its optimum at 0.1, the edge of the values the vehicle takes
    (a current of at most 10 m/s), and the s.e. was read off a column linearised over a step
    about it whose upper end the vehicle refuses: ValueError through the loop. The better fit
    is kept with the refit's exact numbers, its s.e. said not measured, and why."""
    from conftest import make_vehicle

    from nnid.loop.diagnose import Workspace, refit, search_nonlinear

    damping = {"model": None, "coefficients": {"Z:w*abs(w)": -30.0}}
    truth = make_vehicle(damping=damping, current=[0.0, 0.0, 10.0])
    runs = _heave_with_a_little_surge(truth, np.random.default_rng(5))
    vehicle = make_vehicle(damping=damping, current=[0.0, 0.0, 9.9])
    ws = Workspace(*runs, vehicle, None, zoh_midpoint=False, dofs=("w",))
    fit = refit(ws, vehicle, ["Z:w*abs(w)"])
    cand = Candidate("current.z", "current", bounds=(-0.5, 0.5))
    s = search_nonlinear(ws, fit, cand)
    assert s is not None and s.scored and s.value == pytest.approx(0.1, abs=1e-3)
    best = refit(ws, cand.augment(fit.vehicle, s.value), fit.unknowns)
    assert s.drss == fit.rss - best.rss > 0.99 * fit.rss and s.p_value < 1e-6
    assert np.isnan(s.stderr) and s.as_dict()["stderr"]["value"] is None
    with pytest.raises(ValueError):  # the step's upper end: a current above 10 m/s
        cand.augment(fit.vehicle, s.value + 1e-3 * (0.5 - -0.5))
    assert s.unmeasured.startswith("the vehicle refuses current.z = ")
    ResidualLoop(vehicle)._judge(s, 1, fit)
    assert s.reason == (
        f"parameter uncertainty not measured: {s.unmeasured}; its significance cannot be shown"
    )


def test_the_loops_horizons_and_smoothing_read_held_out_runs_at_their_own_step(monkeypatch):
    """Two held-out runs of 120 Hz stamped in whole ms (8, 8, 9 ms), t restarting at 0: read
    over the whole part, the join's negative step threw the rounded clock back on its 8-ms
    median, so the gate's 0.5-s and 1-s horizons were 62 and 125 samples, the scores' 1-s
    k-step 125, and the unexplained structure's Savitzky-Golay window that of 125 Hz. The
    runs' step leaves the join out: 8.33 ms, as each run alone reads."""
    from types import SimpleNamespace

    import nnid.loop.residual_loop as residual_loop
    from nnid.datasets.preprocess import savgol_window

    class Stop(Exception):
        pass

    t = np.round(np.arange(360) / 120 * 1e3) / 1e3
    val = pd.DataFrame({"t": np.r_[t, t], "experiment": ["a"] * t.size + ["b"] * t.size})
    codes = np.repeat([0, 1], t.size)
    data = {"t": val["t"].to_numpy(), "experiment": codes, "nu": np.zeros((val.shape[0], 6))}
    ws = SimpleNamespace(val=val, data_val=data)
    fit = SimpleNamespace(vehicle=None)
    loop = ResidualLoop(load_vehicle(MINIROV), gate_horizon_s=0.5)
    loop.dofs_ = ("w",)
    loop.cleaning_ = SimpleNamespace(steps=[SimpleNamespace(step="derive accelerations")])
    assert loop._gate_modes(ws)[:2] == [("0.5 s ahead", 60), ("1 s ahead", 120)]

    def velocity_scores(ws, vehicle, mode):
        if not isinstance(mode, str):
            raise Stop(mode)
        return {}, {}

    zeros = np.zeros((val.shape[0], 6))
    monkeypatch.setattr(residual_loop, "force_residual", lambda ws, vehicle: zeros)
    monkeypatch.setattr(residual_loop, "nominal_forces", lambda log, vehicle: zeros)
    monkeypatch.setattr(loop, "_velocity_scores", velocity_scores)
    with pytest.raises(Stop) as k:
        loop._scores(ws, fit)
    assert k.value.args == (120,)
    read = []
    monkeypatch.setattr(
        residual_loop, "unexplained_structure", lambda *args, **kw: read.append(args[4:6])
    )
    loop._unexplained(ws, fit)
    [(dt, window)] = read  # one analysed DOF
    assert dt == pytest.approx(1 / 120, rel=1e-5)
    assert window == savgol_window(loop.savgol_window, 120.0, loop.savgol_order)


@pytest.mark.parametrize("filter_lambda", [1.0, None])
def test_training_runs_of_one_sample_each_are_refused_naming_why(filter_lambda):
    """A log whose training runs hold one sample each (a Python caller's; a log file's reader
    refuses a run of one sample) has no step to read: with the filter a division by zero in
    the regression, without it "actuator_lag = nan leaves no valid vehicle", blaming the
    vehicle. One refusal names the runs."""
    from nnid.errors import NnidInputError

    log = effect_log(load_vehicle("seamor"), duration=30, n_experiments=1, seed=3)
    dt = float(log["t"].iloc[1] - log["t"].iloc[0])
    # accelerations given, so that no run is refused for a derivative's window
    log = log.assign(**{f"d{c}": np.gradient(log[c].to_numpy(), dt) for c in "uvwpqr"})
    ones = log.iloc[::3].iloc[:120]
    ones = ones.assign(experiment=[f"s{i}" for i in range(len(ones))])
    held = log.assign(experiment="held")
    joined = pd.concat([held, ones], ignore_index=True)
    loop = ResidualLoop(
        load_vehicle("seamor"), validation_experiments=["held"], filter_lambda=filter_lambda
    )
    with pytest.raises(NnidInputError, match="no training run has two samples") as err:
        loop.fit(joined)
    assert err.value.field == "experiment"


class _GateCandidate:
    """A linear candidate the simulation gate tests stand in: ``augment`` names the vehicle
    after it, or fails as a refit out of the physical range where it is ``refused``."""

    linear, kind = True, "coupled_damping"

    def __init__(self, name: str, refused: bool = False) -> None:
        self.name, self.parameter, self.refused = name, None, refused

    def augment(self, vehicle, value):
        from types import SimpleNamespace

        if self.refused:
            raise ValueError("added mass leaves M indefinite")
        return SimpleNamespace(name=self.name)


def _gate_candidates(n: int, refused: tuple[str, ...] = ()) -> list:
    """``n`` candidates c0, c1, … that passed every test before the gate."""
    from nnid.loop.diagnose import Scored

    out = []
    for k in range(n):
        cand = _GateCandidate(f"c{k}", f"c{k}" in refused)
        s = Scored(cand, 1.0, 0.1, 1e-9, 50.0, 0.3, {"w": 0.3}, 10.0)
        s.admissible, s.reason = True, "passes the tests; ranked below the one added"
        out.append(s)
    return out


def _stub_gate(monkeypatch, error, augment, gate_checks: int):
    """A loop whose gate simulates by ``error(self, ws, vehicle, mode)`` and refits jointly by
    ``augment(self, ws, fit, s)``, and the held-out part and fit it gates on."""
    from types import SimpleNamespace

    import nnid.loop.residual_loop as rl

    monkeypatch.setattr(rl, "vehicle_with", lambda vehicle, values: vehicle)
    monkeypatch.setattr(rl.ResidualLoop, "_simulation_error", error)
    monkeypatch.setattr(rl.ResidualLoop, "_augment", augment)
    ws = SimpleNamespace(val=pd.DataFrame({"t": np.arange(0.0, 10.0, 0.1)}))
    fit = SimpleNamespace(vehicle=SimpleNamespace(name="fit"))
    loop = ResidualLoop(None, gate_checks=gate_checks)
    loop.gates_ = []
    return loop, ws, fit


def test_candidates_beyond_gate_checks_are_not_gated_and_a_gate_failure_is_not_no_effect(
    monkeypatch,
):
    """The gate simulated only the first gate_checks admissible candidates: where all of those
    failed it, the rest stayed admissible, "passes the tests; ranked below the one added", with
    nothing added, and the report opened "No significant effect" over candidates significant
    in the force residual whose simulation alone did not gain."""
    from nnid.reports.loop_report import summary

    gains = {}  # the held-out free-run error with each candidate; 1.0 without
    loop, ws, fit = _stub_gate(
        monkeypatch,
        lambda self, ws, vehicle, mode: gains.get(getattr(vehicle, "name", None), 1.0),
        lambda self, ws, fit, s: "refitted",
        gate_checks=3,
    )
    ranked = _gate_candidates(5)
    assert loop._simulation_gate(ws, fit, ranked) == (None, None)
    assert all("does not improve" in s.reason for s in ranked[:3])
    for s in ranked[3:]:  # never simulated, and nothing was added
        assert not s.admissible and s.reason == "not gated (beyond gate_checks = 3)"
    # one of those gated is added: the rest are ranked below it, gated or not
    gains["c1"] = 0.5
    ranked = _gate_candidates(5)
    chosen, _ = loop._simulation_gate(ws, fit, ranked)
    assert chosen is ranked[1] and chosen.reason == "added"
    assert all(s.admissible and "ranked below the one added" in s.reason for s in ranked[2:])

    # the report: significant candidates the gate turned down are not "no significant effect"
    none = {"free_run_nrmse": {"w": 0.8, "total": 0.8}, "diverged": {},
            "one_step_nrmse": {"w": 0.1, "total": 0.1}, "one_step_diverged": {}}  # fmt: skip
    step = {"added": None, "top": [], "gate": "free run",
            "gate_turned_down": ["c0", "c1", "c2"], "not_gated": ["c3", "c4"]}  # fmt: skip
    result = {"settings": {"k_step_s": 1.0, "gate_checks": 3}, "before": none, "after": none,
              "added": [], "steps": [step], "unexplained": {}}  # fmt: skip
    first = summary(result)[0]
    assert first.startswith(
        "No effect added: significant in the force residual, but no gain in simulation on "
        "held-out data"
    )
    assert "2 more that passed were beyond gate_checks = 3 and not gated (held-out" in first
    assert "(held-out free-run NRMSE 0.8)." in first
    step.update(gate_turned_down=[], not_gated=[])  # nothing passed: the plain verdict
    assert summary(result)[0].startswith("No significant effect")


def test_the_gate_names_why_it_refused_a_candidate_whose_simulation_gained(monkeypatch):
    """gate_turned_down held every candidate the gate simulated and did not add, those whose
    free run gained but whose one-step error grew or whose joint refit left the physical
    range too: the verdict said "no gain in simulation" of them. A candidate whose refit
    failed before any simulation was in no list, and where every gated one did, the verdict
    was "No significant effect", the not-gated ones unsaid."""
    import nnid.loop.residual_loop as rl
    from nnid.loop.diagnose import Step
    from nnid.reports.loop_report import summary

    def error(self, ws, vehicle, mode):  # held-out errors: 1.0 for the fit
        name = getattr(vehicle, "name", None)
        if mode == "one_step":
            return 100.0 if name == "c0" else 1.0  # c0's one-step error grows 100 times
        return 0.5 if name in ("c0", "c3") else 1.0  # c0 and c3 gain in the free run

    def joint(self, ws, fit, s):
        raise ValueError("damping turns positive")

    loop, ws, fit = _stub_gate(monkeypatch, error, joint, gate_checks=4)  # c3's joint refit fails
    scored = _gate_candidates(6, refused=("c1",))
    assert loop._simulation_gate(ws, fit, scored) == (None, None)
    lists = rl.gate_verdicts(Step(scored, None, []))
    assert lists["gate_turned_down"] == ["c2"] and lists["not_gated"] == ["c4", "c5"]
    assert [r["effect"] for r in lists["gate_refused"]] == ["c0", "c1", "c3"]
    assert lists["gate_refused"][0]["reason"].startswith("held-out one-step error grows")
    assert lists["gate_refused"][1]["reason"] == (
        "refit not physical: added mass leaves M indefinite"
    )
    none = {"free_run_nrmse": {"w": 0.8, "total": 0.8}, "diverged": {},
            "one_step_nrmse": {"w": 0.1, "total": 0.1}, "one_step_diverged": {}}  # fmt: skip
    step = {"added": None, "top": [{"effect": s.name} for s in scored], "gate": "free run", **lists}
    result = {"settings": {"k_step_s": 1.0, "gate_checks": 4}, "before": none, "after": none,
              "added": [], "steps": [step], "unexplained": {}}  # fmt: skip
    assert summary(result)[0] == (
        "No effect added: significant in the force residual, but the simulation gate added "
        "none. 4 candidates passed the F-test, the parameter test and the held-out residual "
        "check (the best-ranked, c0), and the simulation gate turned each down: 1 gained "
        "nothing in the held-out simulation, 1 made the held-out one-step error grow, 2 had a "
        "refit that was not physical; 2 more that passed were beyond gate_checks = 4 and not "
        "gated (held-out free-run NRMSE 0.8)."
    )
    # every gated candidate's refit fails before any simulation: not "No significant effect"
    scored = _gate_candidates(6, refused=("c0", "c1", "c2", "c3", "c4", "c5"))
    loop._simulation_gate(ws, fit, scored)
    step.update(rl.gate_verdicts(Step(scored, None, [])), top=[{"effect": s.name} for s in scored])
    assert summary(result)[0].startswith(
        "No effect added: significant in the force residual, but the simulation gate added "
        "none. 4 candidates passed"
    )
    assert "turned each down: 4 had a refit that was not physical; 2 more" in summary(result)[0]


def test_the_reported_model_is_scored_in_the_gates_mode_and_said_where_worse(monkeypatch):
    """The gate accepts an effect on the free run of the candidate's own refit; "after" is the
    joint refit reweighted, which no gate simulated. loop.json said nothing where the two
    differ. ``after_vs_gate`` now holds both in the gate's mode; where the reported one is
    worse (here a stand-in reweight that halves the heave drag) a warning says so, while the
    effect added and the scores reported stay as they are."""
    from dataclasses import replace

    from conftest import make_vehicle

    import nnid.loop.residual_loop as rl
    from nnid.models.parametric import vehicle_with

    quadratic = {"Z:w*abs(w)": -30.0}
    truth = make_vehicle(damping={"model": None, "coefficients": {**quadratic, "Z:w": -20.0}})
    log = pd.concat(_heave_with_a_little_surge(truth, np.random.default_rng(6), "abc"),
                    ignore_index=True)  # fmt: skip
    vehicle = make_vehicle(damping={"model": None, "coefficients": quadratic})

    def fitted(reweight):
        monkeypatch.setattr(rl, "reweight", reweight)
        loop = ResidualLoop(vehicle, dofs=("w",), max_effects=1, nonlinear=False).fit(log)
        return loop, loop.as_dict()

    same, result = fitted(rl.reweight)
    check = result["after_vs_gate"]
    assert result["added"] == ["linear_damping.w"] and check["gate"] == "free run"
    assert check["gated"] == same.added_[0].gate[1]
    assert check["reported"] == result["after"]["free_run_nrmse"]["total"]
    assert not check["worse"] and not any("after_vs_gate" in w for w in result["warnings"])

    reweight = rl.reweight

    def weaker(ws, fit):  # the refit the loop reports, its heave drag halved
        out = reweight(ws, fit)
        drag = out.theta[out.unknowns.index("Z:w*abs(w)")]
        return replace(out, vehicle=vehicle_with(out.vehicle, {"Z:w*abs(w)": 0.5 * drag}))

    _, result = fitted(weaker)
    check = result["after_vs_gate"]
    assert result["added"] == ["linear_damping.w"]  # the verdict stands
    assert check["gated"] == same.added_[0].gate[1]
    assert check["reported"] == result["after"]["free_run_nrmse"]["total"]
    assert check["worse"] and check["reported"] > check["gated"]
    said = [w for w in result["warnings"] if "after_vs_gate" in w]
    assert len(said) == 1 and said[0].startswith(
        "the reported model (the joint refit, reweighted, once linear_damping.w was added) "
        f"scores {check['reported']:.6g} in the held-out free run"
    )
    # no effect added: nothing to compare
    none = ResidualLoop(vehicle, dofs=("w",), max_effects=0, nonlinear=False).fit(log)
    assert none.as_dict()["after_vs_gate"] is None


def test_a_search_whose_optimum_the_vehicle_refuses_found_no_better_fit(monkeypatch):
    """The refit at a 1-D search's optimum was outside any guard: a vehicle that refuses it
    (a refit out of the physical range) raised ValueError through the loop, a traceback where
    every value the search itself scored is refused quietly (scored inf). The search now found
    no better fit there, and the pass names it in ``no_better_fit``, counted as tested."""
    import nnid.loop.diagnose as diagnose
    from nnid.loop.diagnose import search_nonlinear

    vehicle, ws, fit = _heave_fit_beside_a_current()
    cand = Candidate("current.z", "current", bounds=(-0.5, 0.5))
    refit, optimum = diagnose.refit, []

    def refused_at_the_optimum(ws, vehicle, unknowns, held_out=True):
        if held_out:  # the search's own refits read the training part alone
            optimum.append(vehicle)
            raise ValueError("added mass leaves M indefinite")
        return refit(ws, vehicle, unknowns, held_out)

    monkeypatch.setattr(diagnose, "refit", refused_at_the_optimum)
    assert search_nonlinear(ws, fit, cand) is None and len(optimum) == 1
    loop = ResidualLoop(vehicle, dofs=("w",))
    loop.dofs_, loop.gates_ = ("w",), []
    step = loop._step(ws, fit, [cand])
    assert step.no_better_fit == ["current.z"] and step.tested == 1 and step.added is None


def _stub_step(monkeypatch, scored: list, error) -> tuple:
    """A loop whose pass (``_step``) screens ``scored`` as its linear candidates, rescores
    nothing, asks no second opinion, and whose gate simulates by ``error`` (as
    :func:`_stub_gate`); the joint refit is named after the candidate added."""
    import nnid.loop.residual_loop as rl

    loop, ws, fit = _stub_gate(monkeypatch, error, lambda self, ws, fit, s: s.name, gate_checks=30)
    monkeypatch.setattr(rl, "screen_linear", lambda ws, fit, linear: list(scored))
    monkeypatch.setattr(rl, "rescore", lambda ws, fit, ranked: None)
    monkeypatch.setattr(rl, "sindy_opinion", lambda ws, fit, ranked: [])
    loop.nonlinear = False
    fit.unknowns = []
    return loop, ws, fit


def _significance_family(p_values: list[float], improvements: list[float]) -> list:
    """Candidates c0, c1, … that pass every test but the F-test, at these p-values."""
    from nnid.loop.diagnose import Scored

    return [
        Scored(_GateCandidate(f"c{k}"), 1.0, 0.1, p, 50.0, imp, {"w": imp}, 10.0)
        for k, (p, imp) in enumerate(zip(p_values, improvements, strict=True))
    ]


def test_candidates_each_significant_alone_are_not_significant_over_the_family_tested(
    monkeypatch,
):
    """Bonferroni over the candidates tested: of 20 scored, 19 each at p = 0.009, under
    α = 0.01 alone but over α/20 = 5e-4, are not significant, though each would gain in the
    gate (ranked above the one that is); the one at p = 1e-4 < α/20 is, and is added. The
    false-alarm test (19 clean logs of 20) rejects such candidates by its other checks too,
    so it did not fail without the correction."""
    weak = _significance_family([0.009] * 19 + [1e-4], [0.3] * 19 + [0.1])

    def gain(self, ws, vehicle, mode):  # every candidate halves the held-out error
        return 1.0 if vehicle.name == "fit" else 0.5

    loop, ws, fit = _stub_step(monkeypatch, weak, gain)
    step = loop._step(ws, fit, [s.candidate for s in weak])
    assert step.tested == 20
    assert getattr(step.added, "name", None) == "c19" and weak[19].reason == "added"
    for s in weak[:19]:
        assert not s.admissible and s.reason == "not significant (p = 0.009 ≥ 0.0005)", s.reason
        assert s.gate is None  # never simulated


def test_a_candidate_that_helps_one_step_but_not_the_free_run_is_not_added(monkeypatch):
    """The simulation gate: a significant candidate ranked first, whose held-out one-step
    error halves but whose free run gains 2 % (under min_gate_gain = 5 %), is turned down; the
    one ranked next, whose free run gains 10 %, is added. Without the gate the first
    admissible one was added: a column of measured noise explains held-out noise one step
    ahead (errors in variables) and no simulation."""
    from nnid.loop.residual_loop import NO_GAIN

    both = _significance_family([1e-9, 1e-9], [0.3, 0.1])
    errors = {  # held-out velocity NRMSE: (free run, one step)
        "fit": (1.0, 1.0),
        "c0": (0.98, 0.5),
        "c1": (0.9, 1.0),
    }

    def error(self, ws, vehicle, mode):
        return errors[vehicle.name][mode != "free_run"]

    loop, ws, fit = _stub_step(monkeypatch, both, error)
    step = loop._step(ws, fit, [s.candidate for s in both])
    assert getattr(step.added, "name", None) == "c1" and step.fit == "c1"
    assert not both[0].admissible and NO_GAIN in both[0].reason, both[0].reason
    assert both[0].gate == (1.0, 0.98) and loop.gates_ == ["free run"]
