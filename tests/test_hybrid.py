"""The neural-ODE hybrid (issue 15): the Fossen model plus a network for what it misses.

On simulated logs of the loop's effect kinds, built on 'minirov' (not a preset), the shipped
``configs/hybrid.toml`` must at least halve the held-out free-run error of
``configs/fossen_ls.toml`` on the same split; on a log with no undeclared effect it must be no
worse than the physics and its network force must stay under 5 % of the damping force; the
regression of the learned force must name the injected term among its top three for coupled
damping and a current. A jointly trained hybrid keeps complete physics within 10 % of the fit.
"""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch
from conftest import assert_rendered
from torch.func import functional_call
from typer.testing import CliRunner

from nnid import load_model
from nnid.cli import app
from nnid.config import TrainConfig, load_config
from nnid.datasets.log import TAU, write_log
from nnid.datasets.simulator import Autopilot
from nnid.evaluation.prediction import Replay, measured_states
from nnid.loop.scenarios import effect_log
from nnid.models.hybrid import HybridModel
from nnid.pipeline import run_train
from nnid.trainers.adam import Adam
from nnid.trainers.levenberg_marquardt import LevenbergMarquardt
from nnid.vehicle import load_vehicle

CONFIGS = Path(__file__).resolve().parents[1] / "configs"
MINIROV = str(resources.files("nnid.demo_data").joinpath("minirov.toml"))

#: effect -> (value, log seconds): each injected into the plant, absent from the vehicle file
SCENARIOS = {
    "thruster_installation.w.neg": (0.6, 300.0),  # upward heave thrust at 60 % of nominal
    "coupled_damping.N:u*v": (-5.0, 300.0),  # an undeclared coupled damping term
    "actuator_lag": (0.3, 300.0),  # thrusters follow their commands with a 0.3 s lag
    # a tether pulling aft with 4 N; 120 s are enough for it (test/physics error ratio 0.146,
    # against 0.150 with 200 s, 0.120 with 300 s and the 0.5 asked; 2026-11-28 and 12-02),
    # where the lag and the heave thrust loss need 300 s (0.627 and 0.516 with 200 s)
    "external_bias.u": (-4.0, 120.0),
    # a steady current turns with the heading: the training runs must cover the headings the
    # held-out ones fly (a network cannot extrapolate to headings it never saw)
    "current.y": (0.15, 600.0),
}


@pytest.fixture(scope="module")
def minirov():
    return load_vehicle(MINIROV)


#: early-stopping patience in these tests (the shipped config waits 30 epochs): the learning
#: rate follows max_epochs, not the patience, so training is the same epoch for epoch and the
#: best weights are the same unless a new best comes after 15 flat epochs (the w.neg scenario:
#: best epoch 41, stopped at 71 with 30, at 56 with 15; about a fifth of the suite's time)
PATIENCE = 15
#: shorter where a scenario waited little for its best epoch: three epochs more than its
#: longest run without a new best before the epoch it kept (with 15, 2026-11-30: the current's
#: validation error fell at every epoch to its best, the 5th; the clean log's never fell below
#: its start; the coupled term's waited at most 7 epochs, its best the 19th) keeps the same
#: weights, to the bit (the same test and physics errors), and stops 11, 11 and 5 epochs sooner;
#: the tether's 120-s log waited at most 2 epochs before its best, the 14th (2026-12-01): 5
#: stops at the 19th epoch where 15 ran 29, test ratio 0.1457 either way
SHORT_PATIENCE = {"current.y": 4, "none": 4, "coupled_damping.N:u*v": 10, "external_bias.u": 5}
#: the clean log: its network keeps its zero start (no validation epoch beats it, 2026-11-30
#: with 300 s, 2026-12-01 with 120 s: the hybrid is its physics, error ratio 1.0000, force
#: share 0), so 120 s ask of it what 300 s did, in two fifths of the samples
CLEAN_SECONDS = 120.0


def _train(config: str, log_path: Path, patience: int = PATIENCE) -> dict:
    cfg = load_config(CONFIGS / config, TrainConfig)
    if cfg.model.kind == "hybrid":
        cfg.model.trainer.max_fail = patience
    return run_train(cfg, CONFIGS / config, data=str(log_path), vehicle=MINIROV)


#: effect -> (hybrid result, physics result, log path); at module level, not in a fixture:
#: pytest-xdist may tear module fixtures down between the groups a worker runs
_TRAINED: dict[str, tuple] = {}


@pytest.fixture
def runs(minirov, tmp_path_factory):
    """Each scenario's log trained with the shipped hybrid and physics-only configs, once."""

    def get(effect: str):
        if effect not in _TRAINED:
            value, seconds = SCENARIOS.get(effect, (0.0, CLEAN_SECONDS))
            effects = [] if effect == "none" else [(effect, value)]
            log = effect_log(minirov, effects, duration=seconds, dt=0.05, seed=11)
            path = tmp_path_factory.mktemp(effect.replace(":", "_")) / "log.parquet"
            write_log(log, path)
            hybrid = _train("hybrid.toml", path, SHORT_PATIENCE.get(effect, PATIENCE))
            _TRAINED[effect] = (hybrid, _train("fossen_ls.toml", path), path)
        return _TRAINED[effect]

    return get


def _per_log(effects):
    """Parameters grouped by simulated log: under pytest-xdist each log is trained once, on
    one worker, and the logs spread over the workers."""
    return [pytest.param(e, marks=pytest.mark.xdist_group(f"hybrid-{e}")) for e in effects]


def _free(metrics: dict, part: str = "test") -> float:
    return metrics[part]["free_run_nrmse"]["total"]


@pytest.mark.parametrize("effect", _per_log(SCENARIOS))
def test_hybrid_halves_the_physics_free_run_error(effect, runs):
    hybrid, physics, _ = runs(effect)
    h, p = hybrid.metrics, physics.metrics
    assert h["split"]["parts"] == p["split"]["parts"]  # the same held-out experiments
    # the hybrid's own baseline is the physics-only config's fit: one number, two routes
    assert h["baseline"]["test"]["free_run_nrmse"]["total"] == pytest.approx(_free(p), rel=1e-9)
    assert _free(h) <= 0.5 * _free(p), (_free(h), _free(p))


@pytest.mark.xdist_group("hybrid-none")
def test_no_undeclared_effect_no_worse_and_a_small_network_force(runs):
    hybrid, physics, _ = runs("none")
    h = hybrid.metrics
    assert _free(h) <= 1.05 * _free(physics.metrics)
    share = h["correction"]["share_of_damping_force"]
    for part in ("train", "validation", "test"):
        assert share[part]["max"] < 0.05, share


class _PerturbedStart(HybridModel):
    """A hybrid whose network's last layer starts at small seeded weights, not at zero: the
    network adds a force before any training."""

    def _new_dynamics(self, generator=None):
        dynamics = super()._new_dynamics(generator)
        last = dynamics.net.layers[-1]
        draw = torch.Generator().manual_seed(1)
        with torch.no_grad():
            for weights in (last.weight, last.bias):
                weights.copy_(
                    0.05 * torch.randn(weights.shape, generator=draw, dtype=weights.dtype)
                )
        return dynamics


def test_training_on_a_clean_log_pulls_the_network_force_back_toward_the_physics(minirov):
    """The clean-log test above passes from the network's zero start alone (no validation
    epoch beats it), trained or not. From a start that adds a force (its mean square over the
    output scale 5.1e-3 on the training log; the held-out free-run NRMSE 0.098, the physics'
    0.021), 15 epochs on a log with no undeclared effect take the force back toward zero
    (4.7e-4) and the free run back toward the physics (0.044), and the force penalty pulls
    harder (3.1e-4 at a weight of 1; the shipped 1e-3 ends within 1 % of no penalty on this
    log, where the simulation error's own pull dominates). The held-out log also early-stops:
    the kept epoch is the last here, so the pull is the training's, not the choice's."""
    log = effect_log(minirov, duration=20.0, n_experiments=2, dt=0.05, seed=3)
    held = effect_log(minirov, duration=10.0, n_experiments=1, dt=0.05, seed=4)

    def trained(epochs: int, force_penalty: float = 0.0) -> tuple[HybridModel, float]:
        """The hybrid, and its network's mean square force over the output scale on the
        training log."""
        model = _PerturbedStart(
            minirov, trainer=Adam(lr=0.01, max_epochs=epochs), hidden=(8,), memory=(),
            segments=(0.5,), force_penalty=force_penalty, validation_window=2.0,
        ).fit(log, held)  # fmt: skip
        force = model.correction(log).to_numpy() / model.dynamics_.net.out_scale.numpy()
        return model, float(np.mean(force**2))

    model, start = trained(0)
    physics, start_free = model.baseline().score(held)["total"], model.score(held)["total"]
    assert start_free > 3 * physics  # the perturbed start is far from the physics
    model, free = trained(15)
    free_run = model.score(held)["total"]
    assert free < 0.25 * start, (free, start)
    assert free_run - physics < 0.5 * (start_free - physics), (free_run, start_free, physics)
    _, penalised = trained(15, force_penalty=1.0)
    assert penalised < 0.8 * free, (penalised, free)


@pytest.mark.parametrize("effect", _per_log(["coupled_damping.N:u*v", "current.y"]))
def test_the_learned_force_names_the_injected_term(effect, runs):
    hybrid, _, _ = runs(effect)
    explanation = hybrid.metrics["correction"]["explanation"]
    terms = [t["effect"] for t in explanation["terms"]]
    assert effect in terms[:3], terms[:6]
    # the kept terms' shares add up to what they explain together (coef² shares did not)
    shares = sum(t["share"] for t in explanation["terms"])
    assert shares == pytest.approx(explanation["explained"], abs=0.02), explanation


def test_untrained_hybrid_is_its_physics(minirov):
    """The network's last layer starts at zero: before training, the hybrid predicts as the
    parametric fit does (torchdiffeq's 3/8-rule RK4 against the compiled classic RK4) and
    its equation error is the fit's exactly."""
    log = effect_log(minirov, duration=60.0, n_experiments=2, seed=5)
    model = HybridModel(minirov, trainer=Adam(max_epochs=0), segments=(0.5,)).fit(log)
    physics = model.baseline()
    for mode in ("free_run", 3):
        a, b = model.predict(log, mode), physics.predict(log, mode)
        scale = log[["u", "v", "w", "p", "q", "r"]].std()
        err = (a - b)[scale.index].abs().max() / scale
        assert err.max() < 1e-4, err
    # flown under an autopilot too (gains the minirov can follow at 20 Hz: stiff ones make
    # torchdiffeq's 3/8-rule RK4 and the classic one differ by more than this tolerance)
    pilot = Autopilot(kp=[0, 0, 20, 0, 0, 0.5], kd=[20, 20, 20, 0.1, 0.1, 0.2])
    replay = Replay(pilot, log[list(TAU)])
    for mode in ("free_run", 3):
        a, b = model.closed_loop(log, replay, mode), physics.closed_loop(log, replay, mode)
        err = (a - b)[scale.index].abs().max() / scale
        assert err.max() < 1e-4, err
    pd.testing.assert_frame_equal(model.residual(log), physics.residual(log))
    assert float(model.correction(log).abs().to_numpy().max()) == 0.0


@pytest.mark.parametrize(
    ("level", "method", "physics", "hidden"),
    [("force", "rk4", "frozen", (32, 32)), ("acceleration", "nnid_rk4", "joint", (3, 5, 7))],
)
def test_compiled_free_run_is_the_torch_integration(minirov, level, method, physics, hidden):
    """The kernel that scores held-out free runs and predicts (nnid.models.hybrid_kernel) is
    the torch vector field integrated by the same rule (torchdiffeq's 3/8-rule rk4, nnid's
    classic one): random network weights and physics changes δ, a current (ν_r ≠ ν), 5-s
    windows from measured states, an even and an odd number of layers; equal to rounding,
    also at weights given as a dictionary (what early stopping scores)."""
    log = effect_log(minirov, duration=60.0, n_experiments=2, seed=5)
    model = HybridModel(
        minirov, level=level, method=method, physics=physics, hidden=hidden,
        trainer=Adam(max_epochs=0), segments=(0.5,),
    ).fit(log)  # fmt: skip
    dyn = model.dynamics_
    g = torch.Generator().manual_seed(1)
    with torch.no_grad():
        for p in dyn.parameters():
            p.add_(0.3 * torch.randn(p.shape, generator=g, dtype=p.dtype))
        dyn.physics.current.copy_(torch.tensor([0.1, -0.2, 0.05], dtype=torch.float64))
    dyn.physics.forget()
    assert not dyn.physics.field().still and dyn.compiled
    assert (len(dyn.physics.joint) > 0) == (physics == "joint")
    prepared, data = model._data(log, accelerations=False)
    channels = model._channels(prepared, data["tau"])
    starts = np.arange(0, 1000, 50)
    x0 = torch.as_tensor(measured_states(prepared)[starts])
    inputs = torch.as_tensor(channels[starts[:, None] + np.arange(100)[None, :]])
    params = {
        k: v + 0.1 * torch.randn(v.shape, generator=g, dtype=v.dtype)
        for k, v in dyn.named_parameters()
        if v.requires_grad
    }
    with torch.no_grad():
        reference = [dyn(x0, inputs, 0.05), functional_call(dyn, params, (x0, inputs, 0.05))]
    compiled = [dyn.free_run(x0, inputs, 0.05), dyn.free_run(x0, inputs, 0.05, params=params)]
    for a, b in zip(reference, compiled, strict=True):
        assert a.shape == b.shape == (101, starts.size, 12)
        spread = (a - a[0]).abs().amax((0, 1))  # how far each state moved in 5 s
        assert float(spread[6:].min()) > 0.01  # the network and the current act
        assert float(((a - b).abs().amax((0, 1)) / spread.clamp(min=1e-9)).max()) < 1e-9
    assert float((reference[0] - reference[1]).abs().max()) > 1e-3  # the dictionary was used


def test_joint_training_keeps_complete_physics_near_the_fit(minirov):
    """On a log the physics describes completely, joint training (no early stopping, so the
    parameters do move) leaves every added-mass and damping parameter within 10 % of the
    least-squares fit: the prior holds them and the network has nothing to take over."""
    log = effect_log(minirov, duration=120.0, dt=0.05, seed=13)
    model = HybridModel(
        minirov,
        physics="joint",
        segments=(0.25,),
        batch_segments=64,
        trainer=Adam(lr=0.01, max_epochs=15),
        seed=0,
    ).fit(log)
    fitted = model.physics_.params
    joint = model.params
    assert set(joint) == set(fitted)
    moved = {n: joint[n]["value"] / fitted[n]["value"] - 1 for n in fitted}
    assert max(abs(v) for v in moved.values()) <= 0.10, moved
    assert max(abs(v) for v in moved.values()) > 1e-4, moved  # they did train


def test_levenberg_marquardt_trains_a_small_hybrid(minirov):
    """LM (forward-mode Jacobians) needs nnid's own RK4 ('auto' picks it) and lowers the
    held-out free-run error of a tether pull."""
    log = effect_log(minirov, [("external_bias.u", -4.0)], duration=120.0, seed=11)
    parts = {
        p: log[log["experiment"].isin(n)]
        for p, n in (
            ("train", ["run0", "run1", "run2"]),
            ("val", ["run3"]),
            ("test", ["run4", "run5"]),
        )
    }
    model = HybridModel(
        minirov,
        hidden=(8,),
        memory=(),
        segments=(0.25,),
        batch_segments=256,
        # the best validation epoch is the 4th (of 8 or 5: LM's steps do not depend on
        # max_epochs), so 5 keeps the same weights to the bit, test ratio 0.184 either way,
        # in 8 s where 8 epochs took 12.5 (2026-11-29); the 5th shows the best is restored
        trainer=LevenbergMarquardt(max_epochs=5),
    ).fit(parts["train"], parts["val"])
    assert model.describe()["method"] == "nnid_rk4"
    assert (
        model.score(parts["test"])["total"] < 0.5 * model.baseline().score(parts["test"])["total"]
    )
    with pytest.raises(Exception, match="forward-mode"):
        HybridModel(minirov, method="rk4", trainer=LevenbergMarquardt()).fit(parts["train"])


@pytest.mark.xdist_group("hybrid-coupled_damping.N:u*v")
def test_loop_takes_the_trained_hybrid_as_a_second_opinion(runs, tmp_path):
    """`nnid loop --hybrid DIR`: the loop adds the coupled term on its own, and the hybrid's
    learned force, named in the vocabulary, agrees with it in loop.json and the report."""
    effect = "coupled_damping.N:u*v"
    hybrid, _, log = runs(effect)
    hybrid.model.save(tmp_path / "hybrid")
    res = CliRunner().invoke(
        app,
        [
            "loop", "--data", str(log), "--vehicle", MINIROV, "--hybrid", str(tmp_path / "hybrid"),
            "--out", str(tmp_path / "loop"), "--max-effects", "1",
        ],
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    result = json.loads((tmp_path / "loop" / "loop.json").read_text())
    assert result["added"] == [effect]
    named = [t["effect"] for t in result["hybrid_opinion"]["terms"][:3]]
    assert effect in named, named
    assert f"It agrees with the loop on {effect}" in (tmp_path / "loop" / "report.md").read_text()
    # a hybrid of another vehicle was read as this one's missing force without a word
    other = CliRunner().invoke(
        app,
        [
            "loop", "--data", str(log), "--vehicle", "seamor", "--hybrid", str(tmp_path / "hybrid"),
            "--out", str(tmp_path / "loop2"),
        ],
    )  # fmt: skip
    assert other.exit_code == 2
    assert "field '--hybrid': was trained for vehicle 'minirov'; this loop runs 'seamor'" in (
        other.output
    )


def test_cli_train_writes_contract_metrics_and_a_report_that_renders(minirov, tmp_path, chromium):
    """`nnid train configs/hybrid.toml --data --vehicle` (a short budget): model.json and
    tensors.pt that load back to the same predictions, metrics.json with the physics-only
    baseline on the same held-out experiments and the network's force, and report.html with
    the free runs and what the network learned, every figure decoded in headless Chromium."""
    log = effect_log(minirov, [("external_bias.u", -4.0)], duration=100.0, dt=0.05, seed=3)
    write_log(log, tmp_path / "log.parquet")
    cfg = (CONFIGS / "hybrid.toml").read_text().replace("max_epochs = 100", "max_epochs = 3")
    (tmp_path / "h.toml").write_text(cfg)
    out = tmp_path / "out"
    res = CliRunner().invoke(
        app,
        [
            "train", str(tmp_path / "h.toml"), "--data", str(tmp_path / "log.parquet"),
            "--vehicle", MINIROV, "--out", str(out),
        ],
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "physics only" in res.output
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["model"] == "hybrid"
    assert metrics["split"]["requested"] == "auto" and metrics["split"]["by"] == "experiment"
    for part in ("validation", "test"):
        assert set(metrics[part]) >= {"one_step_nrmse", "k_step_nrmse", "free_run_nrmse"}
        assert metrics["baseline"][part]["free_run_nrmse"]["total"] > 0
        assert metrics["correction"]["share_of_damping_force"][part]["max"] >= 0
    test = [e["experiment"] for e in metrics["split"]["parts"]["test"]]
    back = load_model(out)
    held = log[log["experiment"].isin(test)]
    loaded = back.score(held, "free_run", 2.0)
    assert loaded["total"] == pytest.approx(metrics["test"]["free_run_nrmse"]["total"], rel=1e-9)
    # the network's share on the test part is the saved model's, read again on those runs
    share = back.correction_share(held)
    assert share["max"] > 0
    assert metrics["correction"]["share_of_damping_force"]["test"] == pytest.approx(share, rel=1e-9)
    dom = chromium(tmp_path, out / "report.html", dump=True).stdout
    assert 'data-images-ok="yes"' in dom
    assert "What the network learned" in dom and "Against the physics-only baseline" in dom
    chromium(tmp_path, out / "report.html", dump=False)
    assert_rendered(tmp_path / "s.png")


def test_solver_options_and_the_acceleration_level(minirov):
    """The options behind the default path: an untrained hybrid integrated by dopri5 (the
    samples as jump times) predicts as the fit does; three Adam epochs with adjoint gradients
    land on the same weights as with backpropagation; the acceleration-level variant trains
    through the same code and its correction is a force M a_θ."""
    log = effect_log(minirov, [("external_bias.u", -4.0)], duration=60.0, seed=5)
    dopri = HybridModel(minirov, trainer=Adam(max_epochs=0), segments=(0.5,), method="dopri5")
    dopri.fit(log)
    scale = log[["u", "v", "w", "p", "q", "r"]].std()
    err = dopri.predict(log, "free_run") - dopri.baseline().predict(log, "free_run")
    assert (err[scale.index].abs().max() / scale).max() < 1e-4
    trained = {}
    for adjoint in (False, True):
        model = HybridModel(
            minirov,
            hidden=(8,),
            segments=(0.5,),
            adjoint=adjoint,
            trainer=Adam(lr=0.01, max_epochs=3),
        ).fit(log)
        trained[adjoint] = [p.detach().clone() for p in model.dynamics_.net.parameters()]
    for a, b in zip(trained[False], trained[True], strict=True):
        # the adjoint integrates the sensitivities back on the same grid: equal to RK4 order
        assert float((a - b).abs().max()) <= 1e-3 * float(a.abs().max()), (a - b).abs().max()
    assert any(float(p.abs().max()) > 0 for p in trained[True][-2:])  # the last layer moved
    accel = HybridModel(
        minirov, level="acceleration", hidden=(8,), segments=(0.5,), trainer=Adam(max_epochs=3)
    ).fit(log)
    assert accel.describe()["level"] == "acceleration"
    force = accel.correction(log)
    assert list(force.columns) == list("XYZKMN") and float(force.abs().to_numpy().max()) > 0
    # the force is M a_θ: the network's acceleration times M = M_RB + M_A, by hand: M_RB =
    # [[m I, -m S(r_g)], [m S(r_g), I_o]] of the vehicle file, M_A = -diag(X_u̇ … N_ṙ) (Fossen)
    # of the physics the hybrid stands on (its parametric fit's derivatives, else the file's)
    m, (xg, yg, zg) = minirov.mass, minirov.r_g
    s_rg = np.array([[0.0, -zg, yg], [zg, 0.0, -xg], [-yg, xg, 0.0]])
    mass = np.zeros((6, 6))
    mass[:3, :3], mass[:3, 3:], mass[3:, :3] = m * np.eye(3), -m * s_rg, m * s_rg
    mass[3:, 3:] = np.diag(minirov.inertia)
    est = accel.physics_.estimate_
    derivatives = minirov.added_mass | {
        n: float(v) for n, v in zip(est.names, est.theta, strict=True)
    }
    mass -= np.diag([derivatives[f"{f}_{d}dot"] for f, d in zip("XYZKMN", "uvwpqr", strict=True)])
    dyn = accel.dynamics_
    rows, data = accel._data(log, accelerations=False)
    x = torch.as_tensor(measured_states(rows))
    u = torch.as_tensor(accel._channels(rows, data["tau"]))
    with torch.no_grad():
        a_theta = dyn.correction(dyn.physics.field(), x, u).numpy()
    assert np.abs(a_theta).max() > 0
    np.testing.assert_allclose(force.to_numpy(), a_theta @ mass.T, rtol=1e-9, atol=1e-12)


def test_a_network_that_learned_no_force_still_gets_its_report(tmp_path):
    """Two Adam epochs leave the correction at zero: the run writes its model and a report
    that says there is nothing to plot (a figure of 0 rows crashed it, the fit was lost)."""
    root = resources.files("nnid.demo_data")
    log = pd.read_parquet(root.joinpath("demo_minirov_heave.parquet"))
    log = log[log["experiment"].isin(["run0", "run1", "run2"])].groupby("experiment").head(300)
    log.to_csv(tmp_path / "log.csv", index=False)
    cfg = tmp_path / "hybrid.toml"
    cfg.write_text(
        'kind = "train"\nwarmup_s = 2.0\n[split]\nby = "experiment"\ntrain = ["run0"]\n'
        'validation = ["run1"]\ntest = ["run2"]\n[model]\nkind = "hybrid"\ndofs = ["w"]\n'
        'hidden = [4]\n[model.trainer]\nkind = "adam"\nmax_epochs = 2\n'
    )
    args = ["train", str(cfg), "--data", str(tmp_path / "log.csv"), "--vehicle", MINIROV]
    res = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    page = (tmp_path / "out" / "report.html").read_text()
    assert "force is zero on every sample: nothing to plot" in page


@pytest.mark.parametrize("field", ["segments", "validation_window"])
def test_a_segment_or_window_under_one_sample_is_refused(minirov, field):
    """A segment of 1e-6 s at dt = 0.05 s was trained as one sample without a word."""
    from nnid.errors import NnidInputError
    from nnid.trainers.adam import Adam

    log = effect_log(minirov, duration=20.0, n_experiments=2, dt=0.05, seed=3)
    first = log["experiment"] == log["experiment"].iloc[0]
    settings = {"segments": (1.0,), "validation_window": 5.0, field: 1e-6}
    if field == "segments":
        settings["segments"] = (1e-6,)
    model = HybridModel(minirov, trainer=Adam(max_epochs=1), hidden=(4,), **settings)
    with pytest.raises(NnidInputError, match=rf"field '{field}': 1e-06 s is under one sample"):
        model.fit(log[first], log[~first])


def test_a_network_whose_training_diverged_is_said_on_the_console(tmp_path):
    """lr = 1e6: the network's loss became non-finite at once and its stage kept its start, so
    the hybrid scored as its physics fit. The console said "0.114; physics only 0.114" alone,
    as if the network had been trained and learned nothing; only the report's table said."""
    root = resources.files("nnid.demo_data")
    data = tmp_path / "demo.csv"
    # the first 20 s of each demo run, and heave, the one DOF the log moves in: what is said
    # does not depend on either, and a six-DOF network on the whole log took 28 s of the
    # test's (its report drew 24 panels of what it learned), 12 s this way
    log = pd.read_parquet(root.joinpath("demo_minirov_heave.parquet"))
    log.groupby("experiment").head(400).to_csv(data, index=False)
    config = tmp_path / "hybrid.toml"
    config.write_text(
        'kind = "train"\nwarmup_s = 2.0\n[split]\nby = "experiment"\nvalidation = ["run5"]\n'
        'test = ["run6", "run7"]\n[model]\nkind = "hybrid"\ndofs = ["w"]\n'
        'unknowns = ["added_mass", "damping"]\n'
        'physics_trainer = { kind = "ls", filter_lambda = 1.0 }\nhidden = [8]\nsegments = [0.25]\n'
        '[model.trainer]\nkind = "adam"\nlr = 1e6\nmax_epochs = 2\n'
    )
    vehicle = str(root.joinpath("minirov.toml"))
    args = ["train", str(config), "--data", str(data), "--vehicle", vehicle]
    result = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    said = "training diverged in segments of 0.25 s (the loss became non-finite)"
    assert said in " ".join(result.output.split())
    # in the record too: metrics.json's warnings and the report (only the console said it)
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert any(said in w for w in metrics["warnings"])
    # and the report does not explain 0 % of a force that is zero
    report = (tmp_path / "out" / "report.md").read_text()
    assert "The network's force is zero on the training runs" in report
    assert said in report.split("## Warnings")[1]
    calm = config.read_text().replace("lr = 1e6", "lr = 1e-3")
    config.write_text(calm)
    result = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "calm")])
    assert result.exit_code == 0 and "diverged" not in result.output
    report = (tmp_path / "calm" / "report.md").read_text()
    assert "Dominant terms of the learned force on the training runs" in report
    stages = json.loads((tmp_path / "calm" / "metrics.json").read_text())["describe"]["stages"]
    assert "segment_s_trained" not in stages[0]  # 0.25 s fits in every run
    # a segment longer than every run trains on the longest: recorded and said
    config.write_text(
        calm.replace("segments = [0.25]", "segments = [1000.0]").replace(
            "max_epochs = 2", "max_epochs = 1"
        )
    )
    result = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "long")])
    stages = json.loads((tmp_path / "long" / "metrics.json").read_text())["describe"]["stages"]
    assert 0 < stages[0]["segment_s_trained"] < 1000.0
    assert "segments of 1000.0 s (the longest run," in (tmp_path / "long" / "report.md").read_text()


def test_a_hybrid_whose_network_never_trained_gives_no_second_opinion():
    """A network whose training diverged keeps its zero start: the loop's second opinion read
    its zero force as "not explained by any single effect of the vocabulary"."""
    from nnid.reports.loop_report import hybrid_opinion

    zero = {"terms": [], "explained": 0.0, "force_rms": {"w": 0.0, "r": 0.0}}
    text = hybrid_opinion({"hybrid_opinion": zero, "added": []})
    assert "zero on these runs" in text and "no second opinion" in text
    assert "not explained by any single effect" not in text
    some = {**zero, "force_rms": {"w": 0.3, "r": 0.0}}
    assert "not explained by any single effect" in hybrid_opinion({"hybrid_opinion": some})


def test_a_closed_loop_flight_with_memory_starts_each_window_from_the_logs_history(minirov):
    """Flown under a zero-gain autopilot the commands are the log's, so the closed-loop
    prediction is the open-loop one in every mode: k-step windows started the input memory
    from their own first command (0.9-1.6 std apart at k = 3 and 20), where the open-loop
    prediction carries it from the run's start."""
    log = effect_log(minirov, duration=40.0, n_experiments=2, seed=5)
    model = HybridModel(minirov, memory=(0.5,), trainer=Adam(max_epochs=0), segments=(0.5,))
    model.fit(log)
    generator = torch.Generator().manual_seed(1)
    with torch.no_grad():  # a network that uses its memory channel
        for p in model.dynamics_.net.parameters():
            p.add_(0.3 * torch.randn(p.shape, generator=generator))
    replay = Replay(Autopilot(), log[list(TAU)])
    scale = log[["u", "v", "w", "p", "q", "r"]].std()
    for mode in ("free_run", 3, 20):
        a, b = model.predict(log, mode), model.closed_loop(log, replay, mode)
        err = (a - b)[scale.index].abs().max() / scale
        assert err.max() < 1e-6, (mode, err)


def _lagged_windows(model, log, starts, length):
    """Held inputs of ``length`` samples from each start and the states there (windows that
    stay inside one experiment: each starts its lag from the run's lagged force there)."""
    prepared, data = model._data(log, accelerations=False)
    channels = model._channels(prepared, data["tau"])
    x0 = torch.as_tensor(measured_states(prepared)[starts])
    return x0, torch.as_tensor(channels[starts[:, None] + np.arange(length)[None, :]])


@pytest.mark.parametrize(("method", "tolerance"), [("nnid_rk4", 1e-9), ("rk4", 1e-4)])
def test_untrained_hybrid_feels_a_vehicles_actuator_lag_as_its_physics(minirov, method, tolerance):
    """A vehicle file's actuator lag is integrated from the force commanded, exact between
    samples from each window's first lagged sample, as the parametric prediction does: the
    untrained hybrid predicts its fit (to rounding with nnid's classic RK4, to the rule's
    difference with torchdiffeq's 3/8 one), where holding the lagged force's samples was
    0.04-0.18 std away. The compiled kernel is the torch integration of it."""
    from nnid.physics.effects import apply_effect

    truth = apply_effect(minirov, "actuator_lag", 0.3)
    log = effect_log(truth, duration=60.0, n_experiments=2, seed=5)
    model = HybridModel(truth, method=method, trainer=Adam(max_epochs=0), segments=(0.5,))
    model.fit(log)
    physics = model.baseline()
    scale = log[["u", "v", "w", "p", "q", "r"]].std()
    for mode in ("free_run", 3):
        a, b = model.predict(log, mode), physics.predict(log, mode)
        err = (a - b)[scale.index].abs().max() / scale
        assert err.max() < tolerance, (mode, err)
    dyn = model.dynamics_
    g = torch.Generator().manual_seed(1)
    with torch.no_grad():  # a network that acts, on the lagged force's channels too
        for p in dyn.net.parameters():
            p.add_(0.3 * torch.randn(p.shape, generator=g, dtype=p.dtype))
    starts = np.r_[np.arange(0, 501, 50), np.arange(600, 1101, 50)]  # 600 samples a run
    x0, inputs = _lagged_windows(model, log, starts, 100)
    with torch.no_grad():
        reference = dyn(x0, inputs, 0.05)
    compiled = dyn.free_run(x0, inputs, 0.05)
    spread = (reference - reference[0]).abs().amax((0, 1))
    assert float(((reference - compiled).abs().amax((0, 1)) / spread).max()) < 1e-9


def test_a_lagged_vehicle_flies_under_an_autopilot_in_the_hybrid(minirov):
    """A lagged vehicle's closed-loop flight (refused before): the untrained hybrid flies as
    its parametric fit does (to rounding with nnid's classic RK4), and with a network that
    acts, under a zero-gain autopilot (the log's commands), as its own open-loop prediction:
    the stepper carries the force felt, the physics' and the network's channels, from each
    window's start as :meth:`HybridModel._channels` lays them out."""
    from nnid.physics.effects import apply_effect

    truth = apply_effect(minirov, "actuator_lag", 0.3)
    log = effect_log(truth, duration=40.0, n_experiments=2, seed=5)
    model = HybridModel(
        truth, method="nnid_rk4", memory=(0.5,), trainer=Adam(max_epochs=0), segments=(0.5,)
    ).fit(log)
    physics = model.baseline()
    scale = log[["u", "v", "w", "p", "q", "r"]].std()
    pilot = Autopilot(kp=[0, 0, 20, 0, 0, 0.5], kd=[20, 20, 20, 0.1, 0.1, 0.2])
    replay = Replay(pilot, log[list(TAU)])
    for mode in ("free_run", 3):
        a, b = model.closed_loop(log, replay, mode), physics.closed_loop(log, replay, mode)
        err = (a - b)[scale.index].abs().max() / scale
        assert err.max() < 1e-9, (mode, err)
    generator = torch.Generator().manual_seed(1)
    with torch.no_grad():  # a network that acts, on the lagged force and its memory
        for p in model.dynamics_.net.parameters():
            p.add_(0.3 * torch.randn(p.shape, generator=generator))
    replay = Replay(Autopilot(), log[list(TAU)])
    for mode in ("free_run", 3, 20):
        a, b = model.predict(log, mode), model.closed_loop(log, replay, mode)
        err = (a - b)[scale.index].abs().max() / scale
        assert err.max() < 1e-9, (mode, err)
        assert ((a - physics.predict(log, mode))[scale.index].abs().max() > 1e-3 * scale).any()


def test_a_hybrid_trained_on_a_lagged_vehicle_stays_at_the_plant():
    """On noise-free data of a vehicle file that is the plant, lag included (no unknowns),
    the physics predicts the log and training leaves the hybrid there (free run within
    1e-5 of each DOF's peak; torchdiffeq's 3/8 rule against the simulator's classic RK4): the
    held lagged force put it 3-8 % of the peak off after the same training."""
    from nnid.datasets.simulator import simulate
    from nnid.physics.effects import apply_effect

    truth = apply_effect(load_vehicle("seamor"), "actuator_lag", 0.3)
    rng = np.random.default_rng(3)
    inputs = np.zeros((400, 6))
    levels = rng.uniform(-30, 30, size=(20, 3))
    inputs[20:, [0, 1, 5]] = np.repeat(levels, 20, 0)[:380] * [1, 1, 0.2]
    log = simulate(truth, inputs, 0.05)
    model = HybridModel(
        truth, unknowns=(), dofs=["u", "v", "r"], trainer=Adam(max_epochs=3), segments=(0.5,)
    ).fit(log)
    pred = model.predict(log, "free_run")
    for dof in "uvr":
        err = float(np.nanmax(np.abs(pred[dof] - log[dof])))
        assert err < 1e-4 * log[dof].abs().max(), (dof, err)


def test_a_velocity_the_log_lacks_is_left_out_of_the_training_not_taken_as_zero(minirov):
    """Empty u cells (a DVL dropout, rows 50-79 of the first run): the trainer scored them as
    ν = 0 and started segments and validation windows from u = 0, without a word; the
    held-out error at the start was 100 times the clean log's. Now no error row scores them,
    the segments (50, 60, 70) and the window (60) that start there are left out, counted and
    said, and training runs on (a NaN force in the penalty would stop it)."""
    log = effect_log(minirov, duration=20.0, n_experiments=2, dt=0.05, seed=3)
    holes = log.copy()
    holes.loc[holes.index[50:80], "u"] = np.nan
    start = {}
    for name, data in (("clean", log), ("holes", holes)):
        model = HybridModel(
            minirov, trainer=Adam(max_epochs=1), hidden=(4,), memory=(), segments=(0.5,),
            validation_window=1.0,
        )  # fmt: skip
        if name == "holes":
            said = "3 training segments and 1 validation windows start from a velocity"
            with pytest.warns(UserWarning, match=said):
                model.fit(data, data)
        else:
            model.fit(data, data)
        stage = model.stages_[0]
        start[name] = stage["validation"][0]
    assert stage["segments_without_start"] == 3
    assert stage["validation_windows_without_start"] == 1
    assert stage["stop_reason"] == "max_epochs" and "skipped_batches" not in stage
    assert np.isfinite(stage["train"]).all()
    assert start["holes"] < 1.5 * start["clean"], start


def test_the_recorded_training_error_is_the_simulation_errors_not_the_penaltys():
    """One segment, the whole run, trained and held out: its training error at the start is
    its validation error (the same free run). The force penalty's rows counted in the mean:
    it was recorded at half of it (n_y = 6 error rows per sample, 6 penalty rows)."""
    minirov = load_vehicle(MINIROV)
    log = effect_log(minirov, duration=20.0, n_experiments=1, dt=0.05, seed=3)
    model = HybridModel(
        minirov, trainer=Adam(max_epochs=0), hidden=(4,), memory=(), segments=(1000.0,),
        validation_window=None,
    ).fit(log, log)  # fmt: skip
    stage = model.stages_[0]
    assert stage["validation"][0] > 0
    assert stage["train"][0] == pytest.approx(stage["validation"][0], rel=1e-6)


def test_the_lm_hybrids_recorded_training_error_is_the_simulation_errors_too():
    """As the test above with Levenberg-Marquardt: its recorded training error was the
    objective's over the error and the force penalty's rows, half the validation error of the
    same free run (the trainer took no ``recorded``)."""
    minirov = load_vehicle(MINIROV)
    log = effect_log(minirov, duration=2.0, n_experiments=1, dt=0.05, seed=3)
    model = HybridModel(
        minirov, trainer=LevenbergMarquardt(max_epochs=1), hidden=(4,), memory=(),
        segments=(1000.0,), validation_window=None,
    ).fit(log, log)  # fmt: skip
    stage = model.stages_[0]
    assert stage["validation"][0] > 0
    assert stage["train"][0] == pytest.approx(stage["validation"][0], rel=1e-6)


def test_a_diverging_adaptive_solve_is_a_diverged_prediction_not_an_exception(minirov):
    """dopri5 on physics whose quadratic damping has the wrong sign (50 times): torchdiffeq
    asserts on the step that underflows, and predict raised a bare AssertionError where the
    fixed-step rk4 scores the run as diverged. Both now say diverged."""
    log = effect_log(minirov, duration=20.0, n_experiments=1, dt=0.05, seed=3)
    for method in ("rk4", "dopri5"):
        model = HybridModel(
            minirov, trainer=Adam(max_epochs=0), hidden=(4,), memory=(), segments=(0.5,),
            method=method,
        )  # fmt: skip
        with pytest.warns(UserWarning, match="without validation data"):
            model.fit(log)
        physics = model.dynamics_.physics
        with torch.no_grad():
            physics.coefficients.mul_(-50.0)
        physics.forget()
        assert model.score(log)["total"] is None, method
        # a training segment with gradients: NaN states, which Adam skips as a non-finite loss
        prepared, data = model._data(log, accelerations=False)
        x0 = torch.as_tensor(measured_states(prepared)[:1])
        u = torch.as_tensor(model._channels(prepared, data["tau"])[None, :200])
        states = model.dynamics_(x0, u, 0.05)
        assert not bool(torch.isfinite(states[-1]).all()), method
