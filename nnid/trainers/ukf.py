"""Online augmented-state estimation: an unscented Kalman filter on [ν, θ].

Weiss (2013) sets up the Bayes filter (eqs 71-76), its Gaussian/nonlinear form x_{i+1} =
f(x_i, u_i, ω_i), z_i = h(x_i, v_i) (eqs 77-78) and the extended Kalman filter (Jacobians eq 79,
prediction eq 80, innovation eq 81, gain eq 82, update eqs 83-84), then drops it because his
augmented surge state was "not observable" (section V.D, eqs 133-136). This module is that filter
made to work.

**Formulation.** The state is x = [ν_d, θ]: the measured body velocities of the structure's DOF
equations (``structure.dofs``) and its unknown parameters θ in their physical (Fossen
derivative) form, ``X_udot``, ``"X:u*abs(u)"``, ... The process model f (eq 77) is one RK4 step of
the Fossen model of ``structure.parts(θ)`` over the sample interval, input held (as the
simulator does); pose and the velocities of the other DOFs are taken from the log at the start
of the step (exogenous), and θ is a random walk with small process noise. The measurement
(eq 78) is the logged ν_d, so h = [I 0] is linear and the update (eqs 81-84) is the exact
Kalman update; only the prediction needs the unscented transform (which replaces the
Jacobians of eq 79 by sigma points, the alternative Weiss names in L1372). The prediction is
the physics package's own: the model's feature form (:meth:`FossenModel.feature_form`) is
affine in every parameter a :class:`ParametricFossen` accepts (that is what makes the
regression linear), so the forms of ``structure.parts(0)`` and ``structure.parts(e_k)`` are
combined per sigma point and stepped by the compiled RK4 (the inverse mass matrix is inverted
from the combined M). The combination is checked against ``structure.parts(θ).model()`` when
the filter is built.

**Why Weiss's EKF was not observable, and why this one is.** Weiss's state is [u, a₁, a₂] with
a₁ = X_u|u|/(m − X_u̇), a₂ = 1/(m − X_u̇) (eqs 99-100, 134). He applied the *time-invariant*
test rank[C; CA; CA²] = n (eq 135) to the Jacobian A frozen at one sample (eq 136). The
parameter rows of A are zero, so CA² = A₁₁·CA: at a single instant the output senses only the
one combination a₁ u|u| + a₂ X_prop of the two parameters, and the rank is at most 2 < 3 for any
data. (He also reads "det A = 0" as the criterion, which it is not, and A₁₁ should be 2|u|a₁,
not 2√u a₁.) The augmented system is time-varying: its observability over a window is the rank
of O = [H; HΦ₀; HΦ₁Φ₀; …] with the discrete transition Jacobians Φ_k along the trajectory
(:func:`observability_rank`). The parameter columns of O accumulate the sensitivities
∂ν/∂θ = Σ(state transition) · [ν̇-part, u|u|-part, τ-part], so O has full rank exactly when the
regressor vectors along the window span the parameter space: persistent excitation. With a
sign-changing, multi-level input (surge steps of both signs, yaw steps), ν̇ and u|u| are not
collinear and rank O = n_ν + n_θ. What is left non-observable is real: at rest with no input
every parameter column is zero (rank = n_ν, a drop of n_θ); in steady state with constant input
ν̇ = 0 and the added masses drop out (Weiss's frozen-point case). And the parameterisation must
let each parameter change the output independently: estimating the installation gain η⁺ of a
positive-only pure surge force together with X_u̇ and X_u|u| is unobservable for any input
levels (u̇ = (η⁺τ + X_u|u| u|u|)/(m − X_u̇) is invariant to scaling (η⁺, X_u|u|, m − X_u̇) by one
factor) until a force of known gain (the other sign with η⁻ known, or the Coriolis force of a
yaw-sway motion) fixes the scale; so is a product such as weight × r_g, which
:class:`ParametricFossen` already refuses. Weiss's [a₁, a₂] is a one-to-one reparameterisation
of [X_u|u|, X_u̇] for known m, so his filter was observable under excitation too; it was his
test that was not.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from scipy.stats import median_abs_deviation
from sklearn.base import BaseEstimator

from nnid.errors import NnidInputError
from nnid.physics import compiled
from nnid.physics.dofs import DOFS
from nnid.physics.fossen import FeatureForm
from nnid.physics.integrate import rk4
from nnid.trainers.history import Progress, silent
from nnid.trainers.least_squares import Estimate, ExcitationWarning, equation_times

_AFFINE = ("q_rb", "q_a", "g_mat", "theta", "added_mass", "bias")

#: the sample interval (s) the noise defaults were chosen at, 1e-3 and 1e-4 per step there
#: (20 Hz, the Seamor logs of the tests); they are per √s since, the same at every rate
REFERENCE_STEP = 0.05


class _Process:
    """f(x_k, u_k) of Weiss eq 77 for a batch of augmented states: one RK4 step of the Fossen
    model of ``structure.parts(θ)``; the exogenous pose and other velocities come from the log.
    """

    def __init__(self, structure, data: dict[str, np.ndarray]) -> None:
        self.structure = structure
        self.data = data
        self.idx = np.array([DOFS.index(d) for d in structure.dofs])
        self.n_v = self.idx.size
        self.n_p = len(structure.names)
        p = self.n_p
        probes = [np.zeros(p)] + [np.eye(p)[k] for k in range(p)]
        forms, masses, taus = [], [], []
        for th in probes:
            parts = structure.parts(th)
            model = parts.model(check=False)
            forms.append(model.feature_form())
            with torch.no_grad():
                masses.append(model.mass_matrix().numpy())
            taus.append(parts.felt(data))
        base = forms[0]
        for f in forms[1:]:
            if f.codes.shape != base.codes.shape or np.any(f.codes != base.codes):
                raise ValueError("the damping terms differ between parameter probes")
        self.base = base
        self.fields = {
            name: (
                getattr(base, name),
                np.stack([getattr(f, name) - getattr(base, name) for f in forms[1:]], 0),
            )
            for name in _AFFINE
        }
        self.mass = (masses[0], np.stack([m - masses[0] for m in masses[1:]], 0))
        self.tau = (taus[0], np.stack([t - taus[0] for t in taus[1:]], 0))

    def _combine(self, pair: tuple[np.ndarray, np.ndarray], theta: np.ndarray) -> np.ndarray:
        base, delta = pair
        if self.n_p == 0:
            return np.broadcast_to(base, (theta.shape[0], *base.shape)).copy()
        return base + np.tensordot(theta, delta, axes=(1, 0))

    def forms(self, theta: np.ndarray) -> list[FeatureForm]:
        """The feature forms of ``structure.parts(θ_b)`` for a batch ``[B, P]``."""
        fields = {n: self._combine(pair, theta) for n, pair in self.fields.items()}
        m_inv = np.linalg.inv(self._combine(self.mass, theta))
        b0 = self.base
        return [
            FeatureForm(
                m_inv=np.ascontiguousarray(m_inv[b]),
                codes=b0.codes,
                current=b0.current,
                u_c=b0.u_c,
                lag=b0.lag,
                **{n: np.ascontiguousarray(v[b]) for n, v in fields.items()},
            )
            for b in range(theta.shape[0])
        ]

    def full_state(self, nu_d: np.ndarray, k: int) -> np.ndarray:
        """[η, ν] at sample k with the modelled DOFs replaced: ``[B, 12]``."""
        x = np.concatenate([self.data["eta"][k], self.data["nu"][k]])
        out = np.repeat(x[None], nu_d.shape[0], 0)
        out[:, 6 + self.idx] = nu_d
        return out

    def applied(self, theta: np.ndarray, k: int) -> np.ndarray:
        """τ_eff at sample k for each parameter vector ``[B, 6]``."""
        base, delta = self.tau
        if self.n_p == 0:
            return np.repeat(base[k][None], theta.shape[0], 0)
        return base[k] + theta @ delta[:, k, :]

    def step(self, x: np.ndarray, k: int, dt: float) -> np.ndarray:
        """Propagate augmented states ``[B, n_ν + P]`` from sample k to k+1 (Weiss eq 80)."""
        theta = x[:, self.n_v :]
        forms = self.forms(theta)
        x0 = self.full_state(x[:, : self.n_v], k)
        tau = self.applied(theta, k)
        out = x.copy()
        for b, form in enumerate(forms):
            nxt = compiled.integrate_rk4(form, x0[b], tau[b : b + 1], dt)[1]
            out[b, : self.n_v] = nxt[6 + self.idx]
        return out

    def step_direct(self, x: np.ndarray, k: int, dt: float) -> np.ndarray:
        """The same step through ``structure.parts(θ).model(check=False)`` and torch RK4, one
        model per row: the reference the affine combination is checked against."""
        out = x.copy()
        # the force arrays at sample k alone: Parts.felt works sample by sample
        at_k = {key: self.data[key][k : k + 1] for key in ("tau", "tau_neg") if key in self.data}
        for b in range(x.shape[0]):
            theta = x[b, self.n_v :]
            parts = self.structure.parts(theta)
            model = parts.model(check=False)
            x0 = torch.as_tensor(self.full_state(x[b : b + 1, : self.n_v], k)[0])
            tau = torch.as_tensor(parts.felt(at_k))
            with torch.no_grad():
                nxt = rk4(model.rhs, x0, tau, dt, lag=model.actuator_lag)[1].numpy()
            out[b, : self.n_v] = nxt[6 + self.idx]
        return out

    def check(self, theta: np.ndarray, k: int, dt: float, rtol: float = 1e-7) -> None:
        """Raise if the affine combination differs from the directly built model."""
        rng = np.random.default_rng(0)
        x = np.concatenate([self.data["nu"][k, self.idx], theta])[None]
        x = x + rng.normal(0, 0.05, x.shape) * np.concatenate(
            [np.ones(self.n_v), np.abs(theta) + 1e-3]
        )
        a, b = self.step(x, k, dt), self.step_direct(x, k, dt)
        scale = np.abs(b[:, : self.n_v]).max() + 1e-6
        if np.abs(a - b).max() > rtol * scale:
            raise ValueError(
                "the model is not affine in these parameters; the filter cannot combine the "
                "parameter probes"
            )


def _dt(data: dict[str, np.ndarray]) -> np.ndarray:
    """Sample intervals t_{k+1} − t_k (the last repeats the previous one)."""
    t = np.asarray(data["t"], dtype=np.float64)
    if t.size < 2:
        return np.ones_like(t)
    d = np.diff(t)
    return np.append(d, d[-1])


def _boundaries(data: dict[str, np.ndarray]) -> np.ndarray:
    """True at k where sample k+1 starts a new experiment (no prediction across it)."""
    exp = np.asarray(data.get("experiment", np.zeros(len(data["t"]), dtype=int)))
    out = np.zeros(exp.size, dtype=bool)
    out[:-1] = exp[1:] != exp[:-1]
    return out


def noise_level(data: dict[str, np.ndarray], dofs: Sequence[str]) -> np.ndarray:
    """Measurement noise σ per DOF from the logged velocities: a robust (MAD) spread of the
    second differences, divided by √6 (white noise e gives var Δ²e = 6σ²)."""
    idx = [DOFS.index(d) for d in dofs]
    nu = np.asarray(data["nu"])[:, idx]
    if nu.shape[0] < 4:
        return np.full(len(idx), 1e-3)
    d2 = np.diff(nu, 2, axis=0)
    mad = median_abs_deviation(d2, axis=0, scale="normal", nan_policy="omit")
    return np.maximum(mad / np.sqrt(6.0), 1e-6)


@dataclass
class Observability:
    """Rank and singular values of the scaled observability matrix (Weiss eq 135, made
    time-varying): states are ordered [ν_d, θ] as in :class:`UnscentedKalman`."""

    rank: int
    singular_values: np.ndarray
    n_states: int
    names: list[str]

    @property
    def deficiency(self) -> int:
        return self.n_states - self.rank


def transition_jacobians(
    structure,
    data: dict[str, np.ndarray],
    theta: Sequence[float],
    nu: np.ndarray | None = None,
    rel_step: float = 1e-5,
) -> np.ndarray:
    """Φ_k = ∂f/∂x of the augmented process at each sample (Weiss eq 79's A, discrete), by
    central differences of the filter's own process model; ``[N−1, n, n]``. The trajectory is
    the logged ν_d unless ``nu`` ``[N, n_ν]`` is given."""
    proc = _Process(structure, data)
    theta = np.asarray(theta, dtype=np.float64)
    nu_d = np.asarray(data["nu"])[:, proc.idx] if nu is None else np.asarray(nu)
    dts = _dt(data)
    n = proc.n_v + proc.n_p
    scale = np.concatenate([np.ones(proc.n_v) * 1e-2, np.maximum(np.abs(theta), 1e-3)])
    h = rel_step * scale
    out = np.empty((max(nu_d.shape[0] - 1, 0), n, n))
    for k in range(out.shape[0]):
        x = np.concatenate([nu_d[k], theta])
        pert = np.concatenate([x + np.diag(h), x - np.diag(h)], 0)
        f = proc.step(pert, k, float(dts[k]))
        out[k] = ((f[:n] - f[n:]) / (2 * h)[:, None]).T
    return out


def observability_rank(
    structure,
    data: dict[str, np.ndarray],
    theta: Sequence[float],
    start: int = 0,
    length: int | None = None,
    rtol: float = 1e-7,
    measurement_noise: float | Sequence[float] | None = None,
    nu: np.ndarray | None = None,
) -> Observability:
    """Numerical rank of the observability matrix of the linearised augmented system along the
    logged trajectory: O = [H; HΦ_s; HΦ_{s+1}Φ_s; …] over ``length`` samples from ``start``
    (the time-varying form of Weiss eq 135; his eq 136 is one frozen sample of it).

    H = [I 0] picks the measured velocities. Rows are scaled by the measurement noise σ (given,
    or :func:`noise_level`), parameter columns by |θ| (relative changes), so singular values
    compare like with like; the rank counts singular values above ``rtol`` × the largest.
    Full rank n_ν + n_θ needs persistent excitation; at rest with no input it is n_ν.
    The linearisation runs along the logged ν_d, or along ``nu`` ``[N, n_ν]`` (for instance the
    filter's ``history_["nu"]``): measurement noise on the log is itself a faint excitation, so
    judge structural rank on a noise-free or filtered trajectory.
    """
    n_v, n_p = len(structure.dofs), len(structure.names)
    n = n_v + n_p
    stop = len(data["t"]) if length is None else min(start + length, len(data["t"]))
    window = {
        k: (v[start:stop] if isinstance(v, np.ndarray) and v.ndim >= 1 else v)
        for k, v in data.items()
    }
    if _boundaries(window).any():
        raise ValueError("the window spans more than one experiment; give start and length")
    phis = transition_jacobians(
        structure, window, theta, None if nu is None else np.asarray(nu)[start:stop]
    )
    if measurement_noise is None:
        sigma = noise_level(window, structure.dofs)
    else:
        sigma = np.broadcast_to(np.asarray(measurement_noise, dtype=np.float64), (n_v,))
    col = np.concatenate([np.ones(n_v), np.maximum(np.abs(np.asarray(theta, float)), 1e-12)])
    h = np.zeros((n_v, n))
    h[:, :n_v] = np.eye(n_v)
    rows = [h.copy()]
    prod = np.eye(n)
    for phi in phis:
        prod = phi @ prod
        rows.append(h @ prod)
        if np.any(~np.isfinite(prod)):
            raise RuntimeError("the linearised system diverged along the trajectory")
    o = np.concatenate(rows, 0) / np.tile(sigma, len(rows))[:, None] * col[None, :]
    sv = np.linalg.svd(o, compute_uv=False)
    rank = int(np.sum(sv > rtol * sv[0])) if sv.size and sv[0] > 0 else 0
    return Observability(rank, sv, n, [*structure.dofs, *structure.names])


class UnscentedKalman(BaseEstimator):
    """Unscented Kalman filter on the augmented state [ν_d, θ] (Weiss eqs 77-84, with sigma
    points instead of the Jacobians of eq 79).

    Noise levels. ``process_noise``: the velocity model error (an unmodelled acceleration,
    white) as σ per √s, m/s/√s or rad/s/√s (scalar or per DOF): a step of dt adds
    ``process_noise``²·dt to ν's variance. ``parameter_noise``: θ's random walk as σ per √s, a
    fraction of the prior σ: a step adds (``parameter_noise``·σ₀)²·dt. Both are random walks, so
    per second they describe the same drift at every rate (per step, the 50-Hz log of a surge
    dive gave s.e. 1.3-1.8 times those of its 10-Hz log, at one noise density). The defaults,
    4.47e-3 and 4.47e-4, are 1e-3 and 1e-4 per step at 20 Hz (``REFERENCE_STEP``), where they
    were chosen. Per step at another interval δ, σ per √s is σ_step/√δ.
    ``measurement_noise``: σ of each logged velocity sample (m/s, rad/s; scalar or per DOF),
    per sample, not per second: white sensor noise of that σ on every value at whatever rate it
    is logged; None estimates it from the log (:func:`noise_level`). ``theta0``: prior mean
    (None: the vehicle file's values, 0 for a parameter it leaves out); ``theta0_std``: prior σ
    (None: |θ₀|, at least ``min_std``, and where θ₀ = 0, which carries no scale, the diffuse
    :func:`force_scale`). ``alpha``, ``beta``, ``kappa``: the scaled unscented transform.
    ``theta0`` and ``theta0_std`` hold one value per unknown (another length is refused).
    After :meth:`fit`, ``history_`` holds per sample ``t``, ``theta``, ``theta_std`` (scaled as
    the covariance is, below), ``nu`` (filtered ν_d), ``innovation`` (eq 81; NaN where no update
    was made: an experiment's first sample and a velocity that is not finite) and
    ``innovation_std``, its predicted σ (√diag S).

    The covariance of θ̂ is the filter's P at the last sample. θ's random walk
    (``parameter_noise``) makes it that of a slowly drifting θ, so for a constant θ it is
    conservative: measured at the default walk against none on the tests' 60-s surge-yaw Seamor
    log (20 Hz, DVL/gyro noise, ``process_noise`` 1e-4 per 20-Hz step, θ₀ = θ/2; two noise
    seeds), 3.2 times the s.e. for X_udot, 2.1 for N_r|r|, 1.2 for X_u|u| and N_rdot; on 120 s
    of it 5.4, 3.2, 1.6, 1.4 (the walk's share grows with the log). A ``process_noise`` larger
    than the model error widens it further: a mean normalised innovation squared per DOF below
    1/``NIS_TOLERANCE`` is said (and one above it scales the covariance up). Innovations
    correlated over τ > 1 samples (:func:`equation_times` per DOF, of the innovations
    standardised by their predicted σ, pooled over the experiments: a model error the noise
    levels do not describe) widen it by the largest DOF's τ, as least squares widens by its
    residuals' (said above ``CORRELATED_INNOVATIONS``). A factorisation of P that needed
    jitter (it lost positive definiteness) is said once per fit. A parameter the
    data did not inform beyond its prior (its prior σ not halved, in the prior's units, along
    some direction it loads on) gets no standard error and an :class:`ExcitationWarning`: its
    value leans on ``theta0``. A velocity sample that is not finite gives no update there (the
    filter predicts through it; said).
    """

    kind = "ukf"

    def __init__(
        self,
        process_noise: float | Sequence[float] = 1e-3 / REFERENCE_STEP**0.5,
        measurement_noise: float | Sequence[float] | None = None,
        parameter_noise: float = 1e-4 / REFERENCE_STEP**0.5,
        theta0: Sequence[float] | None = None,
        theta0_std: Sequence[float] | None = None,
        min_std: float = 1e-3,
        alpha: float = 0.1,
        beta: float = 2.0,
        kappa: float = 0.0,
        check: bool = True,
    ) -> None:
        self.process_noise = process_noise
        self.measurement_noise = measurement_noise
        self.parameter_noise = parameter_noise
        self.theta0 = theta0
        self.theta0_std = theta0_std
        self.min_std = min_std
        self.alpha = alpha
        self.beta = beta
        self.kappa = kappa
        self.check = check

    def _weights(self, n: int) -> tuple[np.ndarray, np.ndarray, float]:
        lam = self.alpha**2 * (n + self.kappa) - n
        wm = np.full(2 * n + 1, 0.5 / (n + lam))
        wc = wm.copy()
        wm[0] = lam / (n + lam)
        wc[0] = wm[0] + 1.0 - self.alpha**2 + self.beta
        return wm, wc, float(np.sqrt(n + lam))

    def fit(
        self, structure, data: dict[str, np.ndarray], progress: Progress | None = None
    ) -> Estimate:
        """Run the filter over the log; θ̂ and its covariance block at the last sample.
        ``progress(sample, samples, message)`` is called every 1000 samples."""
        report = progress or silent
        proc = _Process(structure, data)
        n_v, n_p = proc.n_v, proc.n_p
        n = n_v + n_p
        names = list(structure.names)
        if self.theta0 is None:
            from nnid.physics.parts import Parts

            vehicle_parts = Parts.from_vehicle(structure.vehicle)
            theta0 = np.array([vehicle_parts.get(nm) for nm in names], dtype=np.float64)
        else:
            theta0 = _prior_vector(self.theta0, "theta0", names)
        if self.theta0_std is None:
            std0 = np.maximum(np.abs(theta0), self.min_std)
            zero = theta0 == 0.0
            if zero.any():
                # |θ₀| as σ was min_std for a parameter the vehicle file leaves out: a prior
                # of 1e-3 (SI) held an absent X_u|u| (truth -61) at 0 against the data
                scale = force_scale(structure, data)
                std0[zero] = np.fmax(scale[zero], self.min_std)
        else:
            std0 = _prior_vector(self.theta0_std, "theta0_std", names)
        r_sigma = (
            noise_level(data, structure.dofs)
            if self.measurement_noise is None
            else np.broadcast_to(np.asarray(self.measurement_noise, dtype=np.float64), (n_v,))
        )
        r_mat = np.diag(r_sigma**2)
        # variances per second: the velocity error and θ's walk are random walks driven by
        # white noise, so a step of dt adds rate·dt (per step, a 50-Hz log of a dive walked 5
        # times as far per second as a 10-Hz one of it, and gave other standard errors)
        q_rate = np.zeros(n)
        q_rate[:n_v] = (
            np.broadcast_to(np.asarray(self.process_noise, dtype=np.float64), (n_v,)) ** 2
        )
        q_rate[n_v:] = (self.parameter_noise * std0) ** 2
        z = np.asarray(data["nu"])[:, proc.idx]
        dts, ends = _dt(data), _boundaries(data)
        n_samples = z.shape[0]
        if self.check and n_samples > 1 and n_p:
            proc.check(theta0, 0, float(dts[0]))
        wm, wc, spread = self._weights(n)
        h = np.zeros((n_v, n))
        h[:, :n_v] = np.eye(n_v)

        x = np.concatenate([z[0], theta0])
        p = np.zeros((n, n))
        p[:n_v, :n_v] = r_mat
        p[n_v:, n_v:] = np.diag(std0**2)
        hist_theta = np.empty((n_samples, n_p))
        hist_std = np.empty((n_samples, n_p))
        hist_nu = np.empty((n_samples, n_v))
        # NaN where no update was made: an experiment's first sample (ν initialised from it)
        # and a sample without a finite velocity; 0 there read as a perfect prediction
        hist_innov = np.full((n_samples, n_v), np.nan)
        hist_innov_std = np.full((n_samples, n_v), np.nan)  # its predicted σ, √diag S
        jitters: list[float] = []  # the relative jitter each repaired factorisation of P needed
        nis, seen_dofs = [], []
        fresh = True  # the first sample of an experiment initialised ν: no update with it
        seen = np.isfinite(z)
        starts = np.r_[True, ends[:-1]]  # ν starts from these samples' measurements
        if not seen[starts].all():
            k = int(np.flatnonzero(~seen[starts].all(1))[0])
            k = int(np.flatnonzero(starts)[k])
            raise NnidInputError(
                f"the first sample of an experiment (sample {k}, t = {data['t'][k]:.6g} s) has "
                "no finite velocity of the filtered DOFs: the filter starts from it",
                field="nu",
                row=k,
            )
        for k in range(n_samples):
            if not fresh and seen[k].any():
                # innovation, gain and update: Weiss eqs 81-84 (Joseph form for eq 84), with
                # the DOFs measured at k (a NaN velocity is no measurement, not a zero one)
                o = seen[k]
                hk, rk = h[o], r_mat[np.ix_(o, o)]
                innov = z[k, o] - x[:n_v][o]
                s = hk @ p @ hk.T + rk
                gain = np.linalg.solve(s, hk @ p).T
                x = x + gain @ innov
                ikh = np.eye(n) - gain @ hk
                p = ikh @ p @ ikh.T + gain @ rk @ gain.T
                hist_innov[k, o] = innov
                hist_innov_std[k, o] = np.sqrt(np.diag(s))
                nis.append(float(innov @ np.linalg.solve(s, innov)))
                seen_dofs.append(int(o.sum()))
            fresh = False
            if k % 1000 == 999:
                report(k + 1, n_samples, "unscented Kalman filter")
            p = 0.5 * (p + p.T)
            hist_theta[k], hist_nu[k] = x[n_v:], x[:n_v]
            hist_std[k] = np.sqrt(np.clip(np.diag(p)[n_v:], 0.0, None))
            if k == n_samples - 1:
                break
            if ends[k]:  # a new experiment: restart ν from its measurement, keep θ
                x = np.concatenate([z[k + 1], x[n_v:]])
                p[:n_v, :] = 0.0
                p[:, :n_v] = 0.0
                p[:n_v, :n_v] = r_mat
                fresh = True
                continue
            # prediction through sigma points: Weiss eq 80 by the unscented transform
            chol, jitter = _cholesky(p)
            if jitter:
                jitters.append(jitter)
            sig = np.concatenate([x[None], x + spread * chol.T, x - spread * chol.T], 0)
            prop = proc.step(sig, k, float(dts[k]))
            if not np.isfinite(prop).all():
                given = np.r_[
                    proc.full_state(x[None, :n_v], k)[0], proc.applied(x[None, n_v:], k)[0]
                ]
                # the log's, only where the filter's own state is finite: a state the update
                # made non-finite is the filter's divergence, not a bad sample
                if np.isfinite(x).all() and not np.isfinite(given).all():
                    raise NnidInputError(
                        f"sample {k} (t = {data['t'][k]:.6g} s) has a pose, velocity of another "
                        "DOF or force that is not finite: the filter's prediction needs them",
                        row=k,
                    )
                raise RuntimeError(
                    f"the filter diverged at sample {k}: widen the noise levels or give a "
                    "closer prior theta0"
                )
            x = wm @ prop
            d = prop - x
            p = (d * wc[:, None]).T @ d + np.diag(q_rate * dts[k])
        cov = p[n_v:, n_v:].copy()
        if jitters:
            worst = max(jitters)
            warnings.warn(
                f"the filter's covariance lost positive definiteness at {len(jitters)} of "
                f"{n_samples - 1 - int(ends[:-1].sum())} predictions: "
                + (
                    f"a jitter of up to {worst:.1g} of each variance was added to factor it"
                    if np.isfinite(worst)
                    else "its negative eigenvalues were set to zero to factor it"
                )
                + "; its parameters may be near collinear or their scales far apart",
                UserWarning,
                stacklevel=2,
            )
        missing = ~seen[~starts].all(1)
        if missing.any():
            gaps = [d for d, o in zip(structure.dofs, seen[~starts].all(0), strict=True) if not o]
            warnings.warn(
                f"{int(missing.sum())} samples have no finite velocity of {', '.join(gaps)}: "
                "the filter predicted through them without that measurement",
                UserWarning,
                stacklevel=2,
            )
        sigma2 = float(np.sum(nis) / np.sum(seen_dofs)) if nis else float("nan")
        if np.isfinite(sigma2) and sigma2 < 1.0 / NIS_TOLERANCE:
            # innovations smaller than the filter predicts: its covariance is wider than the
            # data support (too much process noise); left as it is (conservative), but said
            warnings.warn(
                f"the filter's innovations are {sigma2:.3g} of the variance it predicts "
                "(normalised innovation squared per DOF, 1 for a consistent filter): its "
                "process noise is larger than the model's error and its standard errors are "
                "conservative, wider than the data support; lower process_noise",
                UserWarning,
                stacklevel=2,
            )
        if np.isfinite(sigma2) and sigma2 > NIS_TOLERANCE:
            # innovations larger than the filter predicts: its covariance is overconfident;
            # scaled as least squares scales by the residual variance, and said
            cov, hist_std = _widened(
                cov,
                hist_std,
                sigma2,
                f"the filter's innovations are {sigma2:.3g} times the variance it predicts "
                "(normalised innovation squared per DOF, 1 for a consistent filter): its "
                f"covariance is scaled by {sigma2:.3g}, so the standard errors widen by "
                f"{np.sqrt(sigma2):.2g}x",
            )
        # the filter takes its innovations as white; correlated ones (a model error the noise
        # levels do not describe) hold fewer independent samples than the log has, as least
        # squares' residuals do: widened by their correlation time (equation_times), the
        # largest DOF's, since the filter's P does not split its information by measurement
        # as least squares' sandwich splits it by equation (conservative for the others). Read
        # from the innovations standardised by their predicted σ (white, unit variance for a
        # consistent filter: the large ones of its first samples, while θ is still far off,
        # weigh as much as any) and within each experiment, pooled (a jump between
        # experiments is no correlation), about zero: the filter says its innovations are
        # zero-mean, so a run's offset (an unlogged force) is a model error correlated over
        # the whole run, and widens the s.e. (about each run's mean it entered σ² alone and
        # left the estimates 1.6-1.7 s.e. from the truth, against about 0.9 before)
        times = equation_times(
            hist_innov / hist_innov_std, starts=np.flatnonzero(ends) + 1, about_zero=True
        )
        tau = float(times.max()) if times.size else 1.0
        slow = ", ".join(
            f"{d} {t:.3g}" for d, t in zip(structure.dofs, times, strict=True) if t > 1.0
        )
        cov, hist_std = _widened(
            cov,
            hist_std,
            tau,
            # widened whatever τ; said only above CORRELATED_INNOVATIONS
            f"the filter's innovations are correlated ({slow} samples; a consistent filter's "
            "are white): they hold fewer independent samples than the log, so its covariance "
            f"is widened by {tau:.3g} and the standard errors by {np.sqrt(tau):.2g}x"
            if tau > CORRELATED_INNOVATIONS
            else None,
        )
        # judged on the covariance as reported (scaled and widened): judged before, a parameter
        # at 0.45 of its prior σ passed as measured and was reported with 1.26 times it
        prior_led = _prior_led(cov, std0, names)
        if prior_led:
            given = "theta0_std" if self.theta0_std is not None else "the default prior σ"
            priors = ", ".join(f"{nm} {std0[names.index(nm)]:.3g}" for nm in prior_led)
            warnings.warn(
                "the data did not inform "
                + ", ".join(prior_led)
                + f" beyond the prior ({given}: {priors}; the standard error, widened as "
                "reported, not below half of it along a direction they load on): a prior σ "
                "tighter than the data can move (widen theta0_std), a DOF never excited, or a "
                "combination the input cannot separate; their values lean on theta0 and get no "
                "standard error",
                ExcitationWarning,
                stacklevel=2,
            )
            tied = np.isin(names, prior_led)
            cov[tied, :] = np.nan
            cov[:, tied] = np.nan
        # the path's σ as the reported s.e. (scaled as the covariance is, so that its last row
        # is the s.e. where the data informed the parameter beyond its prior)
        self.history_ = {
            "t": np.asarray(data["t"], dtype=np.float64).copy(),
            "theta": hist_theta,
            "theta_std": hist_std,
            "nu": hist_nu,
            "innovation": hist_innov,
            "innovation_std": hist_innov_std,
        }
        return Estimate(
            names, x[n_v:].copy(), cov, sigma2, int(n_samples * n_v), history=hist_theta.copy()
        )


def force_scale(structure, data: dict[str, np.ndarray]) -> np.ndarray:
    """Each unknown's diffuse prior σ ``[P]``: the value at which it alone would carry the whole
    target of a DOF equation of the batch regression (:meth:`ParametricFossen.regression`,
    φ_k = R(e_k) − R(0), y = −R(0): the applied force less the known rigid-body, Coriolis and
    restoring terms), rms(y_d)/rms(φ_k,d) in the equation d where that is smallest. A parameter
    larger than this would be more force than the log holds, so the truth lies within it; and
    its precision rms(φ)²/rms(y)² is below the data's n·rms(φ)²/σₑ² by the signal-to-noise
    ratio n·rms(y)²/σₑ², so the data lead wherever they inform the parameter at all. NaN for
    a column that is zero (or not finite) in every equation: the log cannot scale it."""
    reg = structure.regression(data)
    m = len(reg.dofs)
    y = reg.y.reshape(-1, m)
    phi = reg.phi.reshape(-1, m, reg.phi.shape[1])
    ok = np.isfinite(y)[:, :, None] & np.isfinite(phi)
    n = np.maximum(ok.sum(0), 1)
    y_rms = np.sqrt(np.where(ok, y[:, :, None] ** 2, 0.0).sum(0) / n)  # [m, P]
    phi_rms = np.sqrt(np.where(ok, phi**2, 0.0).sum(0) / n)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(phi_rms > 0, y_rms / phi_rms, np.inf)
    out = ratio.min(0) if ratio.size else np.full(reg.phi.shape[1], np.inf)
    return np.where(np.isfinite(out) & (out > 0), out, np.nan)


#: a mean normalised innovation squared per DOF above this says the filter is overconfident
NIS_TOLERANCE = 2.0

#: an innovation correlation time (samples) above this is said; any above 1 widens the s.e.
CORRELATED_INNOVATIONS = 2.0


def _prior_vector(value: Sequence[float], field: str, names: list[str]) -> np.ndarray:
    """``theta0`` or ``theta0_std`` as a vector of one value per unknown, refused (naming
    the option, the count and the unknowns) where its length is another: numpy's broadcast
    error named neither."""
    out = np.asarray(value, dtype=np.float64).reshape(-1)
    if out.size != len(names):
        raise NnidInputError(
            f"{field} has {out.size} values; the structure has {len(names)} unknowns "
            f"({', '.join(names)}), one value each in that order",
            field=field,
        )
    return out


#: the data must shrink a parameter direction's prior σ at least this much to be measured
PRIOR_SHRINK = 0.5


def _prior_led(cov: np.ndarray, std0: np.ndarray, names: list[str]) -> list[str]:
    """The parameters that load (|v| > 0.3) on a direction the data did not inform beyond the
    prior: with the prior σ as unit, J = C⁻¹ − I (C the normalised covariance as reported,
    scaled and widened for the innovations; θ's random walk only adds prior-like variance) has
    an eigenvalue below 1/``PRIOR_SHRINK``² − 1 = 3 there, i.e. the reported σ along it is over
    half the prior's. A parameter with no prior spread (σ = 0) is the prior's by construction."""
    fixed = std0 <= 0
    scale = np.where(fixed, 1.0, std0)
    c = cov / np.outer(scale, scale)
    live = ~fixed
    out = set(np.asarray(names)[fixed])
    if live.any():
        sub = c[np.ix_(live, live)]
        info = np.linalg.pinv(0.5 * (sub + sub.T), hermitian=True) - np.eye(int(live.sum()))
        eig, vec = np.linalg.eigh(0.5 * (info + info.T))
        weak = eig < 1.0 / PRIOR_SHRINK**2 - 1.0
        loads = (np.abs(vec[:, weak]) > 0.3).any(1)
        out |= set(np.asarray(names)[live][loads])
    return [nm for nm in names if nm in out]


#: the first jitter, relative to each variance, added to a P that has lost definiteness
JITTER = 1e-12


def _cholesky(p: np.ndarray) -> tuple[np.ndarray, float]:
    """Lower Cholesky factor of P and the jitter it needed (0 if none), relative to each
    variance: P = D C D with D its standard deviations, and a growing jitter is added to the
    unit diagonal of the correlation matrix C, so that each variance grows by the same fraction
    whatever its unit (a jitter scaled by the largest variance, in kg² beside (rad/s)², could
    swamp the smallest). A variance of exactly zero (a parameter held by a zero prior σ) stays
    zero, a row of zeros in the factor; a negative one, or a C no jitter mends, is cut to its
    nonnegative eigenvalues (jitter inf)."""
    var = np.diag(p)
    live = var > 0
    out = np.zeros_like(p)
    if not live.any():
        return out, (np.inf if (var < 0).any() else 0.0)
    d = np.sqrt(var[live])
    c = p[np.ix_(live, live)] / np.outer(d, d)
    eye = np.eye(c.shape[0])
    jitter = 0.0
    for _ in range(8):
        try:
            factor = np.linalg.cholesky(c + jitter * eye)
            break
        except np.linalg.LinAlgError:
            jitter = JITTER if jitter == 0.0 else jitter * 100.0
    else:
        w, v = np.linalg.eigh(c)
        factor, jitter = v @ np.diag(np.sqrt(np.clip(w, 0.0, None))), np.inf
    out[np.ix_(live, live)] = d[:, None] * factor
    return out, (np.inf if (var < 0).any() else jitter)


def _widened(
    cov: np.ndarray, hist_std: np.ndarray, factor: float, why: str | None
) -> tuple[np.ndarray, np.ndarray]:
    """The filter's covariance scaled by ``factor`` and its path's σ by √factor, said where
    ``why`` is given: an overconfident filter's standard errors widened as least squares
    widens them (by the residual variance, by the correlation time)."""
    if why is not None:
        warnings.warn(
            f"{why}; the noise levels or the model structure are off", UserWarning, stacklevel=3
        )
    return cov * factor, hist_std * np.sqrt(factor)
