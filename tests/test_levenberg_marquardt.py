"""Levenberg-Marquardt trainer (issue 6): scipy agreement, physics fit, early stop, chunking."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import torch
from scipy.optimize import least_squares
from torch.func import functional_call

from nnid.config import LevenbergMarquardtSpec
from nnid.errors import NnidInputError
from nnid.models.io_model import seeded_linear
from nnid.threads import torch_threads
from nnid.trainers.adam import Adam
from nnid.trainers.levenberg_marquardt import LevenbergMarquardt, add_gram


def _mlp(sizes: list[int], seed: int) -> torch.nn.Sequential:
    """A tanh network of float64 layers drawn from a generator of its own: torch's global one
    is seeded and drawn by other tests (in an order pytest-xdist's scheduling decides)."""
    gen = torch.Generator().manual_seed(seed)
    layers: list[torch.nn.Module] = []
    for a, b in itertools.pairwise(sizes):
        layers += [seeded_linear(a, b, gen, torch.float64), torch.nn.Tanh()]
    return torch.nn.Sequential(*layers[:-1])


def _linear(n_in: int, n_out: int) -> torch.nn.Linear:
    """A float64 linear layer, its weights drawn from a generator of its own (:func:`_mlp`)."""
    return seeded_linear(n_in, n_out, torch.Generator().manual_seed(0), torch.float64)


def _teacher() -> torch.nn.Sequential:
    """A 1-3-1 tanh network with distinct, unsaturated units: a well-conditioned minimum."""
    teacher = _mlp([1, 3, 1], seed=1)
    with torch.no_grad():
        teacher[0].weight.copy_(torch.tensor([[1.5], [-2.0], [0.7]]))
        teacher[0].bias.copy_(torch.tensor([0.5, -0.3, 1.0]))
        teacher[2].weight.copy_(torch.tensor([[1.0, 0.8, -1.2]]))
        teacher[2].bias.copy_(torch.tensor([0.1]))
    return teacher


def _perturbed(teacher: torch.nn.Sequential, gen: torch.Generator) -> torch.nn.Sequential:
    """A copy of ``teacher`` with N(0, 0.3²) added to every weight, drawn from ``gen``."""
    net = _mlp([1, 3, 1], seed=1)
    net.load_state_dict(teacher.state_dict())
    with torch.no_grad():
        for p in net.parameters():
            p.add_(0.3 * torch.randn(p.shape, generator=gen, dtype=torch.float64))
    return net


def _teacher_problem() -> tuple:
    """Noise-free data of :func:`_teacher` on 200 points, and a perturbed copy of it (seed 0)
    with its starting weights: (teacher, x, y, net, start)."""
    teacher = _teacher()
    x = torch.linspace(-3, 3, 200, dtype=torch.float64).unsqueeze(1)
    with torch.no_grad():
        y = teacher(x)
    net = _perturbed(teacher, torch.Generator().manual_seed(0))
    return teacher, x, y, net, {k: v.clone() for k, v in net.state_dict().items()}


def _quarter(x: torch.Tensor, y: torch.Tensor, epoch: int) -> list:
    """A quarter of the samples, drawn for ``epoch``: one batch."""
    idx = torch.randperm(len(x), generator=torch.Generator().manual_seed(epoch))[: len(x) // 4]
    return [(x[idx], y[idx])]


def _regression_residual(net: torch.nn.Module):
    def residual(params: dict[str, torch.Tensor], batch) -> torch.Tensor:
        x, y = batch
        return (functional_call(net, params, (x,)) - y).reshape(-1)

    return residual


def _flat(net: torch.nn.Module) -> np.ndarray:
    return torch.cat([p.detach().reshape(-1) for p in net.parameters()]).numpy().copy()


@pytest.mark.parametrize(
    ("mode", "damping", "geodesic"),
    [
        ("forward", "trainlm", False),
        ("samples", "trainlm", False),
        ("samples", "nielsen", False),
        ("samples", "trainlm", True),
    ],
)
def test_agrees_with_scipy_lm(mode: str, damping: str, geodesic: bool) -> None:
    teacher = _teacher()
    gen = torch.Generator().manual_seed(0)
    x = torch.linspace(-3, 3, 200, dtype=torch.float64).unsqueeze(1)
    with torch.no_grad():
        y = teacher(x) + 0.01 * torch.randn(x.shape, generator=gen, dtype=torch.float64)
    net = _perturbed(teacher, gen)  # same start for both solvers
    theta0 = _flat(net)
    residual = _regression_residual(net)
    names = [k for k, _ in net.named_parameters()]
    shapes = [p.shape for p in net.parameters()]

    def fun(th: np.ndarray) -> np.ndarray:
        t = torch.from_numpy(th)
        params, o = {}, 0
        for k, s in zip(names, shapes, strict=True):
            params[k] = t[o : o + s.numel()].reshape(s)
            o += s.numel()
        with torch.no_grad():
            return residual(params, (x, y)).numpy()

    ref = least_squares(fun, theta0, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    lm = LevenbergMarquardt(min_grad=1e-13, jacobian=mode, damping=damping, geodesic=geodesic)
    hist = lm.fit(net, residual, [(x, y)])
    theta = _flat(net)
    # At the optimum no step lowers the SSE any more: μ grows to μ_max within an epoch or two.
    # Trials are judged against the SSE computed by the same code path: comparing with the
    # normal equations' SSE (per-sample vmap in "samples" mode, rounding ~1e-17 apart) once
    # accepted null steps until the 1000-epoch cap, on some CPUs and not others.
    assert hist.stop_reason in ("min_grad", "mu_max")
    assert hist.epochs < 200
    cost = 0.5 * float(np.sum(fun(theta) ** 2))
    assert cost == pytest.approx(ref.cost, rel=1e-9)
    np.testing.assert_allclose(theta, ref.x, rtol=1e-5, atol=1e-6)
    assert hist.train[-1] < hist.train[0]


class _Surge(torch.nn.Module):
    """u̇ = (F − k u|u|)/m with unknown k and m (a physics model, not a network)."""

    def __init__(self, k: float, m: float) -> None:
        super().__init__()
        self.k = torch.nn.Parameter(torch.tensor(k, dtype=torch.float64))
        self.m = torch.nn.Parameter(torch.tensor(m, dtype=torch.float64))

    def forward(self, force: torch.Tensor, u0: torch.Tensor, dt: float) -> torch.Tensor:
        def f(u: torch.Tensor, fk: torch.Tensor) -> torch.Tensor:
            return (fk - self.k * u * u.abs()) / self.m

        u, out = u0, [u0]
        for i in range(force.shape[0] - 1):  # RK4 with zero-order-hold force
            fk = force[i]
            k1 = f(u, fk)
            k2 = f(u + 0.5 * dt * k1, fk)
            k3 = f(u + 0.5 * dt * k2, fk)
            k4 = f(u + dt * k3, fk)
            u = u + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
            out.append(u)
        return torch.stack(out)


def test_a_batch_that_changed_between_calls_is_measured_again() -> None:
    """The dense modes kept each batch's residual count by id(batch) for the trainer's life: a
    batch that held other rows at the next call (or a new batch at a freed one's id) read the
    old count, and reverse mode's unit rows no longer matched its residual."""
    _, x, y, net, _ = _teacher_problem()
    residual = _regression_residual(net)
    lm = LevenbergMarquardt(jacobian="reverse")
    batch = [x[:50], y[:50]]
    lm.normal_equations(net, residual, [batch])
    batch[:] = [x, y]  # the same object, 200 rows
    ne = lm.normal_equations(net, residual, [batch])
    ref = LevenbergMarquardt(jacobian="forward").normal_equations(net, residual, [(x, y)])
    assert ne.n == 200
    torch.testing.assert_close(ne.jtj, ref.jtj, rtol=1e-10, atol=1e-12)


def test_physics_parameter_fit_through_rk4() -> None:
    # 15 s of exact data identify k and m as well as 30 s did (k, m within 5e-14 and 2e-14
    # relative, final SSE 8e-28, against the 1e-6 and 1e-12 asked). "auto" takes reverse mode
    # here (rows of J by vmap over one vjp): 0.7 s for this test, against 3.4 s with the
    # forward mode it took before 2026-11-30, whose cost grew with the log's length
    dt = 0.1
    t = torch.arange(150, dtype=torch.float64) * dt
    force = 40 * torch.sin(0.3 * t) + 25 * torch.sin(1.1 * t + 0.4)
    truth = _Surge(k=20.0, m=50.0)
    with torch.no_grad():
        u_meas = truth(force, torch.tensor(0.0, dtype=torch.float64), dt)
    model = _Surge(k=8.0, m=90.0)

    def residual(params: dict[str, torch.Tensor], batch) -> torch.Tensor:
        f, u = batch
        return functional_call(model, params, (f, u[0], dt)) - u

    hist = LevenbergMarquardt(min_grad=1e-14).fit(model, residual, [(force, u_meas)])
    assert float(model.k) == pytest.approx(20.0, rel=1e-6)
    assert float(model.m) == pytest.approx(50.0, rel=1e-6)
    assert hist.train[-1] < 1e-12


def test_validation_early_stop_restores_best() -> None:
    gen = torch.Generator().manual_seed(3)
    x = torch.rand(12, 1, generator=gen, dtype=torch.float64) * 4 - 2
    y = torch.sin(x) + 0.3 * torch.randn(x.shape, generator=gen, dtype=torch.float64)
    xv = torch.linspace(-2, 2, 50, dtype=torch.float64).unsqueeze(1)
    yv = torch.sin(xv)
    net = _mlp([1, 15, 1], seed=0)
    residual = _regression_residual(net)
    hist = LevenbergMarquardt(max_epochs=500).fit(net, residual, [(x, y)], [(xv, yv)])
    assert hist.stop_reason == "validation"
    best = int(np.nanargmin(hist.validation))
    assert hist.best_epoch == best
    assert hist.epochs - best >= 6
    assert all(np.diff(hist.validation[best:]) >= 0)
    with torch.no_grad():
        val_now = float(torch.mean((net(xv) - yv) ** 2))
    assert val_now == pytest.approx(hist.validation[best], rel=1e-12)
    assert hist.train[-1] < hist.train[best]


def _diverged_while_poor(net: torch.nn.Module, limit: float):
    """A residual of batches ``(x, y, free)``: for ``free`` batches it acts like a free run's,
    NaN (the run diverged) while the model's worst error exceeds ``limit``."""
    plain = _regression_residual(net)

    def residual(params: dict[str, torch.Tensor], batch) -> torch.Tensor:
        x, y, free = batch
        r = plain(params, (x, y))
        if free and float(r.abs().max()) >= limit:
            return torch.full_like(r, float("nan"))
        return r

    return residual


def test_a_diverged_validation_at_the_start_is_beaten_by_the_first_finite_one() -> None:
    """The start's validation free run diverged (NaN): the first finite score is the best so
    far. NaN compared False both ways, so the fit used to hand back its start, however far
    training had come."""
    x = torch.linspace(-2, 2, 40, dtype=torch.float64).unsqueeze(1)
    y = torch.sin(x)
    net = _mlp([1, 8, 1], seed=0)
    start = _flat(net)
    residual = _diverged_while_poor(net, 0.5)
    hist = LevenbergMarquardt(max_epochs=30).fit(net, residual, [(x, y, False)], [(x, y, True)])
    assert math.isnan(hist.validation[0])  # recorded as measured, not as a number
    assert hist.best_epoch >= 1 and np.isfinite(hist.validation[hist.best_epoch])
    assert not np.allclose(_flat(net), start)
    with torch.no_grad():
        assert float(torch.mean((net(x) - y) ** 2)) == pytest.approx(
            hist.validation[hist.best_epoch], rel=1e-12
        )


def test_a_validation_run_that_always_diverges_counts_as_failures() -> None:
    """Every validation free run diverged: each accepted epoch is a failure, so the fit stops
    after ``max_fail`` of them and keeps the start (nothing was measured better); it used to run
    on to μ_max or the epoch cap, counting none."""
    x = torch.linspace(-2, 2, 40, dtype=torch.float64).unsqueeze(1)
    y = torch.sin(x)
    net = _mlp([1, 8, 1], seed=0)
    start = _flat(net)
    residual = _diverged_while_poor(net, -1.0)
    lm = LevenbergMarquardt(max_epochs=200, max_fail=4, min_grad=0.0, goal=-1.0)
    hist = lm.fit(net, residual, [(x, y, False)], [(x, y, True)])
    assert hist.stop_reason == "validation diverged" and hist.epochs == 4 and hist.best_epoch == 0
    assert np.allclose(_flat(net), start)


def _one_step(mode: str, budget_mb: float, net: torch.nn.Module, batches) -> tuple:
    state = {k: v.clone() for k, v in net.state_dict().items()}
    lm = LevenbergMarquardt(max_epochs=1, jacobian=mode, memory_budget_mb=budget_mb)
    residual = _regression_residual(net)
    ne = lm.normal_equations(net, residual, batches)
    hist = lm.fit(net, residual, batches)
    theta = _flat(net)
    net.load_state_dict(state)
    return ne, theta, hist


@pytest.mark.parametrize("mode", ["forward", "samples"])
def test_chunking_gives_the_same_step(mode: str) -> None:
    net = _mlp([3, 8, 2], seed=2)
    gen = torch.Generator().manual_seed(1)
    x = torch.randn(400, 3, generator=gen, dtype=torch.float64)
    y = torch.stack([torch.sin(x[:, 0]) * x[:, 1], torch.cos(x[:, 2])], 1)
    batches = [(x[:250], y[:250]), (x[250:], y[250:])]
    p = sum(q.numel() for q in net.parameters())
    ne_full, th_full, h_full = _one_step(mode, 256.0, net, batches)
    tiny = 500 * 7 * 8 / 2**20  # 7 columns of 500 rows, or 500/p rows of p columns
    ne_chunk, th_chunk, h_chunk = _one_step(mode, tiny, net, batches)
    assert h_full.info["peak_jacobian_elements"] == 500 * p
    assert h_chunk.info["peak_jacobian_elements"] <= 500 * 7
    torch.testing.assert_close(ne_chunk.jtj, ne_full.jtj, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(ne_chunk.jtr, ne_full.jtr, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(th_chunk, th_full, rtol=1e-10, atol=1e-12)
    assert h_chunk.train == pytest.approx(h_full.train, rel=1e-12)


def test_modes_agree_and_float32_module() -> None:
    net = _mlp([2, 6, 1], seed=4)
    gen = torch.Generator().manual_seed(2)
    x = torch.randn(200, 2, generator=gen, dtype=torch.float64)
    y = (x[:, :1] * x[:, 1:]).tanh()
    ne_f, th_f, _ = _one_step("forward", 256.0, net, [(x, y)])
    ne_s, th_s, _ = _one_step("samples", 256.0, net, [(x, y)])
    torch.testing.assert_close(ne_f.jtj, ne_s.jtj, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(th_f, th_s, rtol=1e-8, atol=1e-10)
    net32 = net.float()
    residual = _regression_residual(net32)
    hist = LevenbergMarquardt(max_epochs=20).fit(net32, residual, [(x.float(), y.float())])
    assert next(net32.parameters()).dtype == torch.float32
    assert hist.train[-1] < hist.train[0]


@pytest.mark.parametrize("mode", ["forward", "samples"])
def test_large_jacobian_never_materialised(mode: str) -> None:
    net = _mlp([4, 16, 16, 2], seed=5)
    p = sum(q.numel() for q in net.parameters())
    n_samples = 5_000  # J would be 10,000 × 386 = 29 MiB
    gen = torch.Generator().manual_seed(5)
    x = torch.randn(n_samples, 4, generator=gen, dtype=torch.float64)
    y = torch.stack([x[:, 0] * x[:, 1], torch.sin(x[:, 2] + x[:, 3])], 1)
    budget_mb = 1.0
    lm = LevenbergMarquardt(max_epochs=2, jacobian=mode, memory_budget_mb=budget_mb)
    hist = lm.fit(net, _regression_residual(net), [(x, y)])
    budget_elements = int(budget_mb * 2**20) // 8
    n = 2 * n_samples
    assert hist.info["peak_jacobian_elements"] <= budget_elements < n * p
    if mode == "samples":
        assert hist.info["peak_jacobian_rows"] <= budget_elements // p
    else:
        assert hist.info["peak_jacobian_elements"] <= n * (budget_elements // n)
    assert hist.train[-1] < hist.train[0]


def test_progress_reports_each_epochs_scores() -> None:
    """Every epoch's train and validation MSE reach the progress callback as keywords (what
    nnid sweep's ASHA scheduler reads), equal to the History's record."""
    net = _mlp([1, 3, 1], seed=0)
    x = torch.linspace(-2, 2, 60, dtype=torch.float64).unsqueeze(1)
    calls: list[tuple] = []
    hist = LevenbergMarquardt(max_epochs=6).fit(
        net, _regression_residual(net), [(x[::2], torch.sin(x[::2]))],
        [(x[1::2], torch.sin(x[1::2]))], progress=lambda *a, **k: calls.append((a, k)),
    )  # fmt: skip
    assert [a[0] for a, _ in calls] == list(range(1, hist.epochs + 1))
    assert [k["train"] for _, k in calls] == hist.train[1:]
    assert [k["validation"] for _, k in calls] == hist.validation[1:]


def test_l2_penalty_is_the_residual_with_sqrt_lambda_theta_rows() -> None:
    # λ‖θ‖² in the trainer = √λ θ appended to the residual (Tikhonov rows), in every mode
    net = _mlp([2, 5, 1], seed=3)
    gen = torch.Generator().manual_seed(3)
    x = torch.randn(120, 2, generator=gen, dtype=torch.float64)
    y = torch.sin(x[:, :1]) * x[:, 1:]
    lam = 0.7
    base = _regression_residual(net)

    def augmented(params, batch):
        theta = torch.cat([p.reshape(-1) for p in params.values()])
        return torch.cat([base(params, batch), lam**0.5 * theta])

    ref = LevenbergMarquardt(jacobian="forward").normal_equations(net, augmented, [(x, y)])
    for mode in ("forward", "samples"):
        ne = LevenbergMarquardt(jacobian=mode, l2=lam).normal_equations(net, base, [(x, y)])
        torch.testing.assert_close(ne.jtj, ref.jtj, rtol=1e-11, atol=1e-11)
        torch.testing.assert_close(ne.jtr, ref.jtr, rtol=1e-11, atol=1e-11)
        assert ne.sse == pytest.approx(ref.sse, rel=1e-12)
    heavy = _mlp([2, 5, 1], seed=3)
    fit = _regression_residual(heavy)
    hist = LevenbergMarquardt(max_epochs=30, l2=100.0).fit(heavy, fit, [(x, y)], [(x, y)])
    with torch.no_grad():
        plain = float((fit(dict(heavy.named_parameters()), (x, y)) ** 2).mean())
    # validation scores the data alone, and so does the recorded training error (it carried
    # λ‖θ‖²/N, above the validation error of the same data); the steps minimise the whole
    assert hist.validation[hist.best_epoch] == pytest.approx(plain, rel=1e-12)
    assert hist.train[hist.best_epoch] == pytest.approx(plain, rel=1e-12)
    light = _mlp([2, 5, 1], seed=3)
    LevenbergMarquardt(max_epochs=30).fit(light, _regression_residual(light), [(x, y)])
    shrunk = np.linalg.norm(_flat(heavy)) < 0.5 * np.linalg.norm(_flat(light))
    assert shrunk  # the penalty shrinks the weights


def test_recorded_keeps_the_error_rows_of_an_objective_with_penalty_rows() -> None:
    # A residual whose training batches append penalty rows (the hybrid's force penalty): the
    # recorded training error was the objective's mean square over error and penalty rows
    # alike. With ``recorded`` it is the error rows' (here the validation error of the same
    # data), and only the record changes: the same steps, to the bit.
    net = _mlp([2, 5, 1], seed=3)
    gen = torch.Generator().manual_seed(3)
    x = torch.randn(60, 2, generator=gen, dtype=torch.float64)
    y = torch.sin(x[:, :1]) * x[:, 1:]
    base = _regression_residual(net)
    start = {k: v.clone() for k, v in net.state_dict().items()}

    def residual(params, batch):
        x, y, train = batch
        err = base(params, (x, y))
        if not train:
            return err
        out = functional_call(net, params, (x,)).reshape(-1)
        return torch.cat([err, 3.0 * out])  # 60 penalty rows on the network's output

    def error_rows(r: torch.Tensor, batch) -> torch.Tensor:
        return r[: batch[0].shape[0]]

    hists, weights = [], []
    for hook in (None, error_rows):
        net.load_state_dict(start)
        hists.append(
            LevenbergMarquardt(max_epochs=4).fit(
                net, residual, [(x, y, True)], [(x, y, False)], recorded=hook
            )
        )
        weights.append(_flat(net))
    whole, kept = hists
    np.testing.assert_array_equal(weights[0], weights[1])
    assert kept.validation == whole.validation and kept.best_epoch == whole.best_epoch
    assert kept.train[0] == pytest.approx(kept.validation[0], rel=1e-12)
    with torch.no_grad():
        plain = float((base(dict(net.named_parameters()), (x, y)) ** 2).mean())
    assert kept.train[kept.best_epoch] == pytest.approx(plain, rel=1e-12)
    assert whole.train[0] != pytest.approx(kept.train[0], rel=1e-3)  # the penalty's rows counted


def test_l2_center_pulls_toward_its_point_not_toward_zero() -> None:
    # A linear model: LM with λ‖θ − θ_c‖² reaches the closed form (AᵀA + λI)⁻¹(Aᵀb + λθ_c);
    # centred on the least-squares solution the penalty leaves it where it is (no shrinkage)
    gen = torch.Generator().manual_seed(5)
    x = torch.randn(80, 3, generator=gen, dtype=torch.float64)
    y = x @ torch.tensor([[2.0], [-1.0], [0.5]], dtype=torch.float64) + 3.0
    y += 0.1 * torch.randn(80, 1, generator=gen, dtype=torch.float64)
    a = np.hstack([x.numpy(), np.ones((80, 1))])  # weight, then bias: parameters() order
    lam, center = 20.0, np.array([1.0, 1.0, 1.0, -1.0])
    expected = np.linalg.solve(a.T @ a + lam * np.eye(4), a.T @ y.numpy()[:, 0] + lam * center)
    least_squares = np.linalg.lstsq(a, y.numpy()[:, 0], rcond=None)[0]
    for c, want in ((center, expected), (least_squares, least_squares), (None, None)):
        net = _linear(3, 1)
        with torch.no_grad():
            net.weight.zero_()
            net.bias.zero_()
        LevenbergMarquardt(max_epochs=50, l2=lam, l2_center=c, min_grad=0.0).fit(
            net, _regression_residual(net), [(x, y)]
        )
        if c is None:  # plain weight decay: pulled toward zero, away from the data's fit
            want = np.linalg.solve(a.T @ a + lam * np.eye(4), a.T @ y.numpy()[:, 0])
            assert np.linalg.norm(want) < np.linalg.norm(least_squares)
        np.testing.assert_allclose(_flat(net), want, rtol=1e-9, atol=1e-9)
    assert np.abs(expected - least_squares).max() > 0.1  # the centre mattered
    with pytest.raises(NnidInputError, match="l2_center must hold 4 finite values") as info:
        LevenbergMarquardt(l2=1.0, l2_center=[0.0, 0.0]).fit(
            net, _regression_residual(net), [(x, y)]
        )
    assert info.value.field == "l2_center"


def test_l2_leaves_the_unpenalised_parameters_free() -> None:
    # a neural state-space fit's free initial states are no weights: named unpenalised, the
    # penalty leaves them out, here a linear model's bias, and the fit is the closed form
    # (AᵀA + λD)⁻¹Aᵀb with D zero on the bias
    gen = torch.Generator().manual_seed(5)
    x = torch.randn(80, 3, generator=gen, dtype=torch.float64)
    y = x @ torch.tensor([[2.0], [-1.0], [0.5]], dtype=torch.float64) + 3.0
    a = np.hstack([x.numpy(), np.ones((80, 1))])
    lam = 20.0
    want = np.linalg.solve(a.T @ a + lam * np.diag([1.0, 1.0, 1.0, 0.0]), a.T @ y.numpy()[:, 0])
    net = _linear(3, 1)
    LevenbergMarquardt(max_epochs=50, l2=lam, min_grad=0.0).fit(
        net, _regression_residual(net), [(x, y)], unpenalised=["bias"]
    )
    np.testing.assert_allclose(_flat(net), want, rtol=1e-9, atol=1e-9)
    with pytest.raises(NnidInputError, match="unpenalised names x0, which are not") as info:
        LevenbergMarquardt(l2=1.0).fit(net, _regression_residual(net), [(x, y)], unpenalised=["x0"])
    assert info.value.field == "unpenalised"


def test_batches_drawn_per_epoch_judge_that_epochs_steps() -> None:
    # Noise-free data of a network of the same shape: every subset of samples shares the
    # minimum, so LM on a fresh quarter of the samples each epoch must reach it on all of them.
    teacher, x, y, net, start = _teacher_problem()
    residual = _regression_residual(net)
    calls: list[int] = []

    def draw(epoch: int) -> list:
        calls.append(epoch)
        return _quarter(x, y, epoch)

    # one epoch: the same step as LM on that epoch's batches given as fixed batches
    LevenbergMarquardt(max_epochs=1).fit(net, residual, draw)
    one_drawn = _flat(net)
    net.load_state_dict(start)
    LevenbergMarquardt(max_epochs=1).fit(net, residual, draw(0))
    np.testing.assert_array_equal(one_drawn, _flat(net))

    net.load_state_dict(start)
    calls.clear()
    hist = LevenbergMarquardt(max_epochs=60, min_grad=0.0).fit(net, residual, draw)
    assert calls == list(range(hist.epochs))  # each epoch's draw, once, in order
    with torch.no_grad():
        full = float(torch.mean((net(x) - y) ** 2))
        first = float(torch.mean((teacher(x) - functional_call(teacher, start, (x,))) ** 2))
    assert full < 1e-12 * first
    # the reported training error is that of the epoch's own draw
    ((xb, yb),) = draw(hist.epochs - 1)
    with torch.no_grad():
        assert hist.train[-1] == pytest.approx(float(torch.mean((net(xb) - yb) ** 2)), rel=1e-9)


def test_curvature_from_a_subset_keeps_every_samples_gradient_and_error() -> None:
    # Subsampled curvature: JᵀJ from the drawn samples, scaled to all; the gradient and the SSE
    # that judges a step from every sample. Noise-free teacher data, so the minimum is shared.
    teacher, x, y, net, start = _teacher_problem()
    residual = _regression_residual(net)

    def quarter(epoch: int) -> list:
        return _quarter(x, y, epoch)

    # curvature from every sample: plain LM's step (the reverse-mode gradient is its Jᵀr), with
    # the λ‖θ‖² rows added once, not scaled
    LevenbergMarquardt(max_epochs=1, l2=0.3).fit(
        net, residual, [(x, y)], curvature_batches=lambda e: [(x, y)]
    )
    whole = _flat(net)
    net.load_state_dict(start)
    LevenbergMarquardt(max_epochs=1, l2=0.3).fit(net, residual, [(x, y)])
    np.testing.assert_allclose(whole, _flat(net), rtol=1e-10, atol=1e-12)
    # a quarter's curvature: the same gradient as plain LM, a different step
    net.load_state_dict(start)
    plain = LevenbergMarquardt(max_epochs=1).fit(net, residual, [(x, y)])
    plain_step = _flat(net)
    net.load_state_dict(start)
    sub = LevenbergMarquardt(max_epochs=1).fit(net, residual, [(x, y)], curvature_batches=quarter)
    assert sub.extra["gradient"][0] == pytest.approx(plain.extra["gradient"][0], rel=1e-10)
    assert np.abs(_flat(net) - plain_step).max() > 1e-6
    # it converges on every sample, and reports the error of every sample
    net.load_state_dict(start)
    hist = LevenbergMarquardt(max_epochs=60, min_grad=0.0).fit(
        net, residual, [(x, y)], curvature_batches=quarter
    )
    with torch.no_grad():
        full = float(torch.mean((net(x) - y) ** 2))
        first = float(torch.mean((teacher(x) - functional_call(teacher, start, (x,))) ** 2))
    assert full < 1e-12 * first
    assert hist.train[-1] == pytest.approx(full, rel=1e-9, abs=1e-30)


class _Point(torch.nn.Module):
    def __init__(self, start: list[float]) -> None:
        super().__init__()
        self.t = torch.nn.Parameter(torch.tensor(start, dtype=torch.float64))


def test_geodesic_pull_is_the_residuals_second_directional_derivative() -> None:
    """Jᵀ r_δδ against the analytic value for r_i = a_i x² + b_i x y + c_i y³ − d_i."""
    gen = torch.Generator().manual_seed(3)
    a, b, c, d = torch.randn(4, 7, generator=gen, dtype=torch.float64)

    def residual(params: dict[str, torch.Tensor], batch) -> torch.Tensor:
        x, y = params["t"]
        return a * x**2 + b * x * y + c * y**3 - d

    theta = torch.tensor([0.7, -1.3], dtype=torch.float64)
    delta = torch.tensor([0.4, 0.9], dtype=torch.float64)
    x, y = theta
    dx, dy = delta
    rdd = 2 * a * dx**2 + 2 * b * dx * dy + 6 * c * y * dy**2
    jac = torch.stack([2 * a * x + b * y, b * x + 3 * c * y**2], dim=1)
    lm = LevenbergMarquardt()
    layout = lm._layout(_Point([0.0, 0.0]))
    # two batches: the pull is summed over them
    got = lm._curvature_pull(residual, theta, layout, [None, None], delta)
    torch.testing.assert_close(got, 2 * jac.T @ rdd, rtol=1e-12, atol=1e-12)


def test_geodesic_acceleration_follows_the_rosenbrock_valley() -> None:
    """Rosenbrock's valley (Moré, Garbow & Hillstrom problem 1 with a 100 weight, from their
    start (−1.2, 1)): the curved canyon where Transtrum & Sethna's acceleration pays. Both
    reach the minimum (1, 1); the accelerated trainer in fewer than half the iterations."""

    def residual(params: dict[str, torch.Tensor], batch) -> torch.Tensor:
        x, y = params["t"]
        return torch.stack([1 - x, 100 * (y - x**2)])

    epochs = {}
    for geodesic in (False, True):
        point = _Point([-1.2, 1.0])
        hist = LevenbergMarquardt(max_epochs=1000, min_grad=1e-10, geodesic=geodesic).fit(
            point, residual, [None]
        )
        torch.testing.assert_close(point.t.detach(), torch.ones(2, dtype=torch.float64))
        epochs[geodesic] = hist.epochs
    assert epochs[True] < epochs[False] / 2


def test_geodesic_ratio_must_be_positive() -> None:
    trainer = LevenbergMarquardtSpec(kind="lm", geodesic=True, geodesic_ratio=0.5).build()
    assert (trainer.geodesic, trainer.geodesic_ratio) == (True, 0.5)
    with pytest.raises(NnidInputError, match="geodesic_ratio"):
        LevenbergMarquardt(geodesic=True, geodesic_ratio=0.0).fit(
            _Point([0.0, 0.0]), lambda p, b: p["t"] - 1.0, [None]
        )


@pytest.mark.parametrize("threads", [1, 2])
def test_add_gram_accumulates_the_normal_equations_block_by_block(threads):
    # JᵀJ and Jᵀr (Weiss eqs 54-61) added block by block into the same system equal those of
    # the stacked rows, on either path (numpy's BLAS with one torch thread, torch's with more)
    rng = np.random.default_rng(0)
    jac = torch.as_tensor(rng.standard_normal((700, 37)))
    r = torch.as_tensor(rng.standard_normal(700))
    jtj = torch.full((37, 37), 2.0, dtype=torch.float64)  # what earlier blocks left there
    jtr = torch.full((37,), -1.0, dtype=torch.float64)
    with torch_threads(threads):
        add_gram(jtj, jtr, jac[:300], r[:300])
        add_gram(jtj, jtr, jac[300:].T.contiguous().T, r[300:])  # column-major rows too
    np.testing.assert_allclose(jtj.numpy(), 2.0 + jac.numpy().T @ jac.numpy(), atol=1e-10)
    np.testing.assert_allclose(jtr.numpy(), -1.0 + jac.numpy().T @ r.numpy(), atol=1e-10)


def test_without_validation_the_kept_epoch_is_the_last_accepted_step() -> None:
    # A linear least-squares problem: LM reaches the minimum in a few steps, then every step
    # is rejected (no lower SSE exists) until μ passes its maximum. The parameters kept are
    # those of the last accepted step, and best_epoch says which epoch that was, not the last
    # epoch run (the train report reads a budget stop at best_epoch = epochs as "still
    # improving").
    gen = torch.Generator().manual_seed(0)
    x = torch.rand(40, 1, generator=gen, dtype=torch.float64)
    y = 3 * x - 1 + 0.1 * torch.randn(x.shape, generator=gen, dtype=torch.float64)
    net = _linear(1, 1)
    residual = _regression_residual(net)
    hist = LevenbergMarquardt(max_epochs=40, min_grad=0.0, mu_max=1e6).fit(net, residual, [(x, y)])
    # a step is accepted only if it lowers the SSE: the epochs whose training error fell are
    # accepted ones (a last step that lowers it by an ulp may not show in the mean square)
    accepted = [k for k in range(1, len(hist.train)) if hist.train[k] < hist.train[k - 1]]
    assert accepted and accepted[-1] <= hist.best_epoch < hist.epochs
    assert hist.train[hist.best_epoch] == min(hist.train)
    assert hist.stop_reason in {"mu_max", "max_epochs"}


@pytest.mark.parametrize("mode", ["forward", "samples"])
def test_a_training_error_that_is_not_finite_stops_as_non_finite_not_as_a_stall(mode) -> None:
    # A training window's free run that overflowed (here a residual that is inf from the
    # start): no μ gives a step, and the stop used to be "mu_max", which the report words as
    # "stalled: LM found no step"; it is Adam's "non-finite loss", before any solve, and the
    # parameters are left as they were.
    net = _linear(1, 1)
    start = _flat(net)
    x = torch.ones(4, 1, dtype=torch.float64)

    def residual(params, batch):
        return functional_call(net, params, (batch,)).reshape(-1) * math.inf

    hist = LevenbergMarquardt(max_epochs=20, jacobian=mode).fit(net, residual, [x])
    assert hist.stop_reason == "non-finite loss"
    assert hist.epochs == 0 and not math.isfinite(hist.train[0])
    np.testing.assert_array_equal(_flat(net), start)


@pytest.mark.parametrize("trainer", [LevenbergMarquardt, Adam])
def test_max_epochs_0_records_the_start_and_leaves_the_weights(trainer) -> None:
    """LM with ``max_epochs=0`` stopped before its first Jacobian and recorded nothing: no
    training error, no validation error, where Adam records the start. Both record it (the
    mean square of the residual at the starting weights) and keep those weights; a negative
    ``max_epochs``, and a ``max_fail`` of 0, are refused by both, naming it."""
    _, x, y, net, start = _teacher_problem()
    residual = _regression_residual(net)
    with torch.no_grad():
        mse = float(((net(x) - y) ** 2).mean())
        held = float(((net(x[::2]) - y[::2]) ** 2).mean())
    hist = trainer(max_epochs=0).fit(net, residual, [(x, y)], [(x[::2], y[::2])])
    assert hist.stop_reason == "max_epochs" and hist.epochs == 0 and hist.best_epoch == 0
    assert hist.train == [pytest.approx(mse, rel=1e-12)] and len(hist.time) == 1
    assert hist.validation == [pytest.approx(held, rel=1e-12)]
    assert all(torch.equal(v, start[k]) for k, v in net.state_dict().items())
    with pytest.raises(NnidInputError, match="not -1") as err:
        trainer(max_epochs=-1).fit(net, residual, [(x, y)])
    assert err.value.field == "max_epochs"
    # max_fail 0: LM stopped before any validation error and said "validation diverged"
    with pytest.raises(NnidInputError, match="not 0") as err:
        trainer(max_fail=0).fit(net, residual, [(x, y)], [(x, y)])
    assert err.value.field == "max_fail"
