"""Caccia, Indiveri & Veruggio (2000): two-step identification of one uncoupled DOF ξ.

The 1-DOF model (Caccia eq. 3) is m_ξ ξ̇ = −k_ξ ξ − k_ξ|ξ| ξ|ξ| + η_ξ(μ) φⁿ_ξ + ν_ξ with Caccia's
positive drag coefficients, m_ξ the inertia *including* added mass, φⁿ the nominal force from the
thrust curves and allocation, η the installation coefficient of the thrust mapping mode μ and
the sign of φⁿ, and ν a disturbance whose mean ν̄ is identified.

**Step 1, steady state (eqs 7-10; heave: eq. 20).** At steady state eq. 3 is the algebraic
relation 0 = −k ξ − k₂ ξ|ξ| + η φⁿ + ν̄ (eq. 7). Every plateau of constant nominal input gives one
row of y = Hθ (eqs 8-9): reference rows (η ≡ 1, open-water direction of the reference mode)
``[ξ, ξ|ξ|, −1, −i, 0…]`` with y = φⁿ; rows of any other mode/direction group g
``[ξ, ξ|ξ|, −1, −i, …, −φⁿ (column of η_g), …]`` with y = 0; θ = [k, k₂, ν̄, Δν, η_g…] (eq. 10).
The ``−i`` column is Caccia's eq.-20 extension for experiments i = 0, 1, … with a different
weight each (ΔW per experiment); it is present only when the log has several settings.
θ̂, σ̂ and the percentile error 100 σ̂/|θ̂| follow eqs 11-12 through
:func:`nnid.trainers.least_squares.solve_least_squares`; a parameter above 51.02 % is
statistically insignificant at 95 % (L279). By default (``weighting="speed"``) the rows are
weighted by 1/(k_L σ_ξ*)², σ_ξ* the standard error of the plateau's steady speed and
k_L = k + 2k₂|ξ*| from a first ordinary fit (a speed error δξ moves row j by k_L δξ): a short,
slow plateau then counts less than a long, fast one, and σ̂ from eq. 12 (now a scale factor)
stays honest when the plateaus differ that much; ``weighting="none"`` is Caccia's ordinary LS.

Plateau rule (the paper only says steady-state runs were used, Fig. 4): within each experiment
the log is cut where the nominal force φⁿ_ξ changes (constant input = equal to within 1e-9 of
its scale). In each constant-input segment the position χ (depth for heave) is differentiated
twice by a Savitzky-Golay filter fitted *inside the segment only* (``settle_window`` s, order
``settle_order``), so that no window straddles a step; the segment's settled part is its longest
run of consecutive samples with |χ̈| ≤ ``settle_accel`` (default 2e-3 m/s², about four times
the SG acceleration noise of a 2-cm, 10-Hz depth-meter with the 10-s window), and it counts when
that run lasts at least ``min_plateau`` s and holds at least ``MIN_PLATEAU_SAMPLES`` samples
(on fewer, the steady speed's standard error is not measured: with three samples it was ~0,
with four 18 % of the speeds lay beyond 2 s.e., and the step-1 row weights 1/σ² let such a
plateau outweigh the rest). Plateaus that never settle are dropped;
:attr:`CacciaTwoStep.plateaus_` lists those used. The steady speed ξ* is estimated from the
position by least squares, as Caccia did (Fig. 5, L111): by default (``speed="asymptote"``) as
the slope of χ(t) = c + ξ* t + A e^{−(t−t₀)/τ} fitted over the settled run (τ on a grid,
polished; its s.e. counts τ and the F test's choice of the line: :func:`_asymptote`), i.e.
with the tail of the first-order approach to steady state modelled. A heavy open-frame vehicle
near zero speed settles slowly (ROMEO heave: t_c = m_w/k_L up to 1150/45 ≈ 26 s) while a depth
record pins the slope to ~1e-4 m/s, so an unmodelled residual transient would bias k and W by
several reported σ. ``speed="slope"`` is Caccia's plain LS slope of χ over the run (weights its
middle most), ``"mean"`` the mean SG velocity over it.

**Step 2, inertia (eqs 13-19).** A d-optimal sinusoid φⁿ = φ̂ + Δφ sin(ω_opt t) (eq. 15),
ω_opt = 1/(√3 t_c), t_c = m_ξ/k_L, k_L = k + 2 k₂ |ξ*| (eqs 13-14), is designed from the step-1
drag and a prior inertia (:meth:`CacciaTwoStep.design_sinusoid`, using
:class:`nnid.datasets.excitation.DOptimalSine`). Eq. 3 integrated over the run is linear in
θ = [m_ξ, m_ξ ξ₀ + k χ₀, b] (eqs 16-19): y_k = ϕ_k − k χ_k − k₂ I_k, H row = [ξ_k, −1, −t_k] with
ϕ = ∫ η φⁿ (exact for the zero-order-hold input), χ the position, I = ∫ ξ|ξ| and ξ from the
SG-filtered position; b absorbs ν̄ (weight − buoyancy for heave) and integration bias (L169).
ξ is a regressor, so its noise attenuates m̂_ξ by about σ²_noise/var(ξ) (errors in variables):
the default SG (5 s, order 4; Caccia used 4-6 s, L321/L327) keeps that below 1 % for a 2-cm
depth record while leaving the sinusoid undistorted.
With ``correlated=True`` (default) σ̂ of this step is widened by the residual's integrated
autocorrelation time (:func:`nnid.trainers.least_squares.correlation_time`): eq. 11 assumes
white residuals, and an integrated equation driven by SG velocities has strongly correlated
ones; ``correlated=False`` is Caccia's plain eq. 11. σ̂(m_ξ) is conditional on the step-1 drag,
as in the paper.

**Output names** (:meth:`CacciaTwoStep.fit_logs`) follow the vehicle file, with Fossen signs:
``"Z:w" = −k_w``, ``"Z:w*abs(w)" = −k_w|w|`` (negative = drag), ``"eta.w.neg"`` (installation
coefficient of upward thrust; ``eta.<dof>.<mode>.<pos|neg>`` when several modes are given),
``"Z_wdot" = −(m_w − m)``, and for the restoring/disturbance terms
``"weight_minus_buoyancy"`` = Caccia's W (W − B of experiment 0, force along +z = down, the
Fossen restoring force −g₃ at zero attitude) and ``"delta_weight"`` = ΔW per experiment. For the
other DOFs the mean disturbance is ``"external_bias.<dof>"`` and its step ``"delta_bias.<dof>"``.
The Caccia-signed estimates are kept in :attr:`CacciaTwoStep.steady_` and
:attr:`CacciaTwoStep.inertia_`.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from itertools import pairwise
from typing import Any, Literal

import numpy as np
import pandas as pd
from scipy.integrate import cumulative_trapezoid
from scipy.optimize import minimize_scalar

from nnid.datasets.arrays import log_arrays
from nnid.datasets.excitation import PRBS, DOptimalSine
from nnid.datasets.log import ANGLES
from nnid.datasets.measurement import Measurement
from nnid.datasets.preprocess import (
    off_steps,
    savgol_interp,
    savgol_window,
    true_runs,
    unwrap_finite,
)
from nnid.datasets.simulator import simulate, simulate_config
from nnid.errors import NnidInputError
from nnid.evaluation.persistence import combined_excitation
from nnid.physics.dofs import DOFS, FORCES
from nnid.physics.thrusters import Actuation, apply_installation
from nnid.trainers.history import Progress, silent
from nnid.trainers.least_squares import Estimate, correlation_time, solve_least_squares
from nnid.trainers.regression import Regression

POSITION_OF = {"u": "x", "v": "y", "w": "z", "p": "phi", "q": "theta", "r": "psi"}
"""The position χ integrated from each DOF's velocity (level attitude, Caccia's 1-D trials)."""

MIN_PLATEAU_SAMPLES = 10
"""Fewest samples of a settled run that count as a plateau: the asymptote fit has four
parameters (c, ξ*, A, τ); of 400 noisy straight-line speeds 1-2 % lay beyond 2 s.e. from 10
samples on (the four-parameter model's s.e., conservative on a plain line), with 4 samples
18 %, with 3 the s.e. was ~0 (the default 10 s at 1 Hz spans 11)."""


def _one_sinusoid_run(arrays: Mapping[str, Any]) -> None:
    """Refuse a sinusoid log of several experiments, naming them. Pieces a gap cut one run into
    (``experiment_runs``, :func:`nnid.datasets.log.run_of`) are said as such: eqs 16-19
    integrate eq. 3 from the run's start, θ₂ = m_ξ ξ₀ + k χ₀ holding its one initial state, and
    ϕ = ∫ η φⁿ across a hole integrates a force nobody logged; the step is not fitted on the
    longest piece alone unasked, which would drop the rest without a word."""
    codes = np.asarray(arrays["experiment"])
    used = np.unique(codes)
    if used.size <= 1:
        return
    names = arrays.get("experiment_names")
    names = [str(names[c]) if names is not None else str(c) for c in used]
    runs = arrays.get("experiment_runs")
    runs = {str(runs[c]) for c in used} if runs is not None else set(names)
    if len(runs) > 1:
        raise NnidInputError(
            f"the sinusoid log must hold one experiment (one run of the d-optimal sinusoid), "
            f"not {len(names)}: {names}",
            field="sinusoid",
        )
    t = np.asarray(arrays["t"], dtype=np.float64)
    spans = [(t[codes == c].min(), t[codes == c].max()) for c in used]
    holes = ", ".join(f"{end:g}-{start:g} s" for (_, end), (start, _) in pairwise(spans))
    longest = int(np.argmax([b - a for a, b in spans]))
    raise NnidInputError(
        f"the sinusoid run '{runs.pop()}' was cut at time gaps into {len(names)} pieces "
        f"{names} (holes at t = {holes}): Caccia's step 2 integrates the motion over one "
        f"uninterrupted run (eqs 16-19) and cannot cross a hole nobody measured; log the "
        f"sinusoid without a gap, or fit step 2 on one piece (the longest is "
        f"'{names[longest]}', {spans[longest][1] - spans[longest][0]:g} s)",
        field="sinusoid",
    )


# --- step 1: plateaus and the steady-state regression ------------------------------------------


@dataclass
class Plateau:
    """One steady-state run: constant nominal input ``force`` and its settled ``speed``."""

    experiment: str
    setting: int  # Caccia's i in eq. 20 (weight setting / experiment index)
    mode: str  # thrust mapping mode label ("" = the only one)
    force: float  # nominal φⁿ_ξ
    speed: float  # steady ξ*
    speed_std: float  # s.e. of the steady speed (_asymptote: τ free, post-selection; white noise)
    start: float  # settled run [start, end] in s
    end: float
    n: int

    @property
    def direction(self) -> str:
        """'pos' for φⁿ ≥ 0, 'neg' otherwise (the sign the installation coefficient uses)."""
        return "pos" if self.force >= 0 else "neg"


def _asymptote(t: np.ndarray, x: np.ndarray, f_crit: float = 3.0) -> tuple[float, float]:
    """Steady speed and its standard error from the position over a settled run: the slope of
    χ = c + ξ* t + A exp(−(t − t₀)/τ) fitted by LS, i.e. the asymptote of a first-order approach
    to steady state (Caccia eq. 3 at constant input), when the exponential tail is significant
    (F statistic of its two parameters above ``f_crit``, ≈ 95 %); else the plain LS slope of
    c + ξ* t. τ minimises the profile RSS: a 40-point grid up to half the run, polished by a
    bounded 1-D search between the best point's neighbours. The s.e. is the nonlinear-LS one of
    the exponential model, σ̂² (JᵀJ)⁻¹ with n − 4 degrees of freedom, J holding
    ∂χ/∂τ = A t/τ² e^{−t/τ} beside the columns of c, ξ*, A, and it is reported on both branches
    (the line's own when larger): the F test's choice is made on the same data, and a weak
    transient it drops biases the line's slope by several of the line's s.e. (post-selection
    inference, Leeb & Pötscher 2005). White noise, 300 draws a case (20-300 samples, τ 0.1-0.5
    of the run, transient 0-30 × the noise): the ±1.96 s.e. band held 10-94 % of the speeds
    with τ fixed and the line's own s.e., now 55-99 % (mean 89 %), lowest for weak transients
    as slow as half the run; on the simulated ROMEO campaign (11 seeds, 329 plateaus) 27 % lay
    beyond 1.96 s.e., now 5 %."""
    tc = t - t[0]
    n, span = tc.size, float(tc[-1])
    ones = np.ones_like(tc)

    def fit(tau: float) -> tuple[float, np.ndarray, np.ndarray]:
        h = np.stack([ones, tc, np.exp(-tc / tau)], 1)
        coef, *_ = np.linalg.lstsq(h, x, rcond=None)
        r = x - h @ coef
        return float(r @ r), coef, h

    taus = np.geomspace(max(span / 200, 1e-3), span / 2, 40)
    profile = np.array([fit(tau)[0] for tau in taus])
    i = int(np.argmin(profile))
    # the profile RSS(τ) is smooth: its minimum lies between the best grid point's neighbours
    lo, hi = np.log(taus[max(i - 1, 0)]), np.log(taus[min(i + 1, taus.size - 1)])
    polish = minimize_scalar(
        lambda lt: fit(float(np.exp(lt)))[0], bounds=(lo, hi), method="bounded"
    )
    tau = float(np.exp(polish.x)) if polish.fun < profile[i] else float(taus[i])
    rss, coef, h = fit(tau)
    j = np.column_stack([h, coef[2] * tc / tau**2 * h[:, 2]])
    scale = np.linalg.norm(j, axis=0)  # columns of very different size (1, t, e, A t/τ² e)
    scale[scale == 0] = 1.0
    inv = np.linalg.pinv((j / scale).T @ (j / scale), hermitian=True) / np.outer(scale, scale)
    std = float(np.sqrt(rss / max(n - 4, 1) * inv[1, 1]))
    h0 = h[:, :2]
    coef0, *_ = np.linalg.lstsq(h0, x, rcond=None)
    r0 = x - h0 @ coef0
    rss0 = float(r0 @ r0)
    if rss < rss0 and (rss0 - rss) / 2 / max(rss / max(n - 4, 1), 1e-300) > f_crit:
        return float(coef[1]), std
    std0 = float(np.sqrt(rss0 / max(n - 2, 1) * np.linalg.inv(h0.T @ h0)[1, 1]))
    return float(coef0[1]), max(std, std0)


#: this many missing-sample gaps in a row are a stretch logged at a slower rate, refused; fewer
#: are a logger's dropouts, cut (a lone sample between two is no plateau of any length)
SLOW_GAPS = 4


def _sample_interval(
    t: np.ndarray, joins: np.ndarray, run: str, cut_gaps: bool = True
) -> tuple[float, np.ndarray]:
    """The typical sampling interval of one run's time stamps ``t`` (``joins``: where its rows
    resume after another run's, not an interval) and where samples are missing: the
    one-sample rule of the rest of nnid (:func:`~nnid.datasets.preprocess.off_steps`: the
    median, or a coarsely rounded clock's step, 120 Hz stamped in ms steps 8, 8, 9 ms), an
    interval longer than that. The Savitzky-Golay filters count time in samples, so anything
    else that is not uniform is refused, naming ``run``: an interval shorter than one (jitter,
    a faster rate) or :data:`SLOW_GAPS` gaps in a row (a slower rate, whose every sample
    would be cut off alone and dropped; fewer are dropouts, a lone sample between two of them
    too short for any plateau); a gap too unless ``cut_gaps``."""
    d = np.diff(t)
    within = ~joins
    dt, off = 1.0, np.empty(0, np.int64)  # no interval: nothing to count in
    if within.any():
        dt, off, _ = off_steps(t, within=within)
    missing = np.zeros(d.size, bool)
    bad = np.zeros(d.size, bool)
    missing[off] = d[off] > dt
    bad[off] = d[off] < dt
    in_row = np.convolve(missing.astype(np.int64), np.ones(SLOW_GAPS, np.int64), "valid")
    bad[: in_row.size] |= in_row == SLOW_GAPS
    if not cut_gaps:
        bad |= missing
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise NnidInputError(
            f"column t of {run} is not uniformly sampled: {d[k]:.4g} s from t = {t[k]:.6g} to "
            f"{t[k + 1]:.6g} s against {dt:.4g} s elsewhere, and the Savitzky-Golay filter of "
            "Caccia's procedure counts time in samples; resample the log to one rate"
            + (" (a plateau is cut where samples are missing)" if cut_gaps else ""),
            field="t",
        )
    return dt, missing


def find_plateaus(
    t: np.ndarray,
    position: np.ndarray,
    force: np.ndarray,
    experiment: np.ndarray,
    names: Sequence[str] | None = None,
    settings: Sequence[int] | None = None,
    modes: np.ndarray | None = None,
    settle_window: float = 10.0,
    settle_order: int = 2,
    settle_accel: float = 2e-3,
    min_plateau: float = 10.0,
    speed: Literal["slope", "mean", "asymptote"] = "asymptote",
    angle: bool = False,
) -> list[Plateau]:
    """Steady-state plateaus of constant nominal input (rule in the module docstring).

    ``experiment`` holds integer codes 0, 1, … (``names`` their labels); the weight setting of
    code c is ``settings[c]`` (default c, Caccia's experiment number i); ``modes`` labels each
    sample with its thrust mapping mode. A code that comes back after another's rows is one
    experiment (one setting) but not one run: no plateau spans the other's rows, nor a gap
    where samples are missing; time stamps that are otherwise not uniform are refused
    (:func:`_sample_interval`). ``angle``: the position is an attitude angle (p q r), which
    readers keep wrapped at ±π; each constant-input segment is unwrapped before it is
    differentiated and fitted (:func:`~nnid.datasets.preprocess.unwrap_finite`).
    """
    t = np.asarray(t, np.float64)
    position = np.asarray(position, np.float64)
    force = np.asarray(force, np.float64)
    experiment = np.asarray(experiment)
    scale = max(float(np.max(np.abs(force))), 1e-12)
    mode_labels = np.full(t.size, "", dtype=object) if modes is None else np.asarray(modes)
    plateaus: list[Plateau] = []
    for code in pd.unique(experiment):
        idx = np.flatnonzero(experiment == code)
        te, xe, fe, me = t[idx], position[idx], force[idx], mode_labels[idx]
        label = str(names[int(code)]) if names is not None else str(code)
        # cut where the input or mode changes, and where the experiment's rows resume after
        # another's or samples are missing: the same input on both sides of that join or gap
        # is two runs, not one plateau (the filter would take the gap for one interval)
        joins = np.diff(idx) != 1
        dt, gaps = _sample_interval(te, joins, f"experiment {label}")
        cuts = (np.abs(np.diff(fe)) > 1e-9 * scale) | (me[1:] != me[:-1]) | joins | gaps
        change = np.r_[True, cuts]
        starts = np.flatnonzero(change)
        stops = np.r_[starts[1:], te.size]
        window = savgol_window(settle_window, 1.0 / dt, settle_order, "settle_window")
        for a, b in zip(starts, stops, strict=True):
            if (b - a) * dt < min_plateau or b - a <= window:
                continue
            seg_t, seg_x = te[a:b], xe[a:b]
            if angle:  # a wrap is a 2π step no vehicle made: it broke the settled run
                seg_x = unwrap_finite(seg_x)
            acc = savgol_interp(seg_x, window, settle_order, 2, dt)
            runs = true_runs(np.abs(acc) <= settle_accel)
            if not runs:
                continue
            r0, r1 = max(runs, key=lambda r: r[1] - r[0])
            # the run lasts (r1 − r0 − 1) dt (the plateau's end − start), to within rounding
            span = (r1 - r0 - 1) * dt
            if span < min_plateau * (1 - 1e-9) or r1 - r0 < MIN_PLATEAU_SAMPLES:
                continue
            tt, xx = seg_t[r0:r1], seg_x[r0:r1]
            tc = tt - tt.mean()
            slope = float(tc @ (xx - xx.mean()) / (tc @ tc))
            resid = xx - xx.mean() - slope * tc
            slope_std = float(np.sqrt(resid @ resid / max(tt.size - 2, 1) / (tc @ tc)))
            if speed == "mean":
                vel = savgol_interp(seg_x, window, settle_order, 1, dt)
                value = float(vel[r0:r1].mean())
            elif speed == "asymptote":
                value, slope_std = _asymptote(tt, xx)
            else:
                value = slope
            c = int(code)
            plateaus.append(
                Plateau(
                    experiment=str(names[c]) if names is not None else str(c),
                    setting=int(settings[c]) if settings is not None else c,
                    mode=str(me[a]),
                    force=float(fe[a]),
                    speed=value,
                    speed_std=slope_std,
                    start=float(tt[0]),
                    end=float(tt[-1]),
                    n=int(tt.size),
                )
            )
    return plateaus


def caccia_names(dof: str) -> tuple[str, str, str, str]:
    """Caccia-signed step-1 names: k_ξ, k_ξ|ξ|, ν̄ (W for heave), Δν (ΔW for heave)."""
    if dof == "w":
        return "k_w", "k_w|w|", "W", "delta_W"
    return f"k_{dof}", f"k_{dof}|{dof}|", f"nu_{dof}", f"delta_nu_{dof}"


def eta_name(dof: str, mode: str, direction: str) -> str:
    """``eta.<dof>.<pos|neg>`` (vehicle-file name), or ``eta.<dof>.<mode>.<pos|neg>``."""
    return f"eta.{dof}.{direction}" if not mode else f"eta.{dof}.{mode}.{direction}"


def steady_state_regression(
    plateaus: Sequence[Plateau],
    dof: str = "w",
    reference: Sequence[tuple[str, str]] = (("", "pos"),),
    force_eta_one: bool = False,
    terms: Sequence[str] = ("linear", "quadratic"),
    disturbance: bool = True,
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """H, y and Caccia-signed names of eqs 8-10 (eq. 20 for heave with several settings).

    ``reference`` lists the (mode, direction) groups with η ≡ 1 (open water; eq. 20: downward
    heave thrust); each other group present gets its own η column. ``force_eta_one`` makes
    every group a reference (η = 1 everywhere, Caccia Fig. 6). ``terms`` picks the drag terms
    (``"linear"`` ξ, ``"quadratic"`` ξ|ξ|); ``disturbance`` the ν̄ column (and Δν when the
    plateaus come from several settings).
    """
    if not plateaus:
        raise NnidInputError("no steady-state plateau was found in the log", field="steady_state")
    bad = set(terms) - {"linear", "quadratic"}
    if bad or not terms:
        raise ValueError(f"terms are 'linear' and/or 'quadratic', got {list(terms)}")
    k1, k2, nu, dnu = caccia_names(dof)
    xi = np.array([p.speed for p in plateaus])
    phi = np.array([p.force for p in plateaus])
    setting = np.array([p.setting for p in plateaus], np.float64)
    cols, names = [], []
    if "linear" in terms:
        cols.append(xi)
        names.append(k1)
    if "quadratic" in terms:
        cols.append(xi * np.abs(xi))
        names.append(k2)
    if disturbance:
        cols.append(-np.ones_like(xi))
        names.append(nu)
        if np.unique(setting).size > 1:
            cols.append(-setting)
            names.append(dnu)
    refs = {tuple(r) for r in reference}
    groups = [(p.mode, p.direction) for p in plateaus]
    is_ref = np.array(
        [force_eta_one or g in refs or p.force == 0 for g, p in zip(groups, plateaus, strict=True)]
    )
    y = np.where(is_ref, phi, 0.0)
    for g in dict.fromkeys(g for g, r in zip(groups, is_ref, strict=True) if not r):
        member = np.array([gg == g and not r for gg, r in zip(groups, is_ref, strict=True)])
        cols.append(np.where(member, -phi, 0.0))
        names.append(eta_name(dof, *g))
    return np.stack(cols, 1), y, names


# --- step 2: the integrated regression -------------------------------------------------------


def integrated_regression(
    t: np.ndarray,
    position: np.ndarray,
    force: np.ndarray,
    k_linear: float,
    k_quadratic: float,
    eta_pos: float = 1.0,
    eta_neg: float = 1.0,
    velocity_window: float = 5.0,
    velocity_order: int = 4,
    force_neg: np.ndarray | None = None,
    angle: bool = False,
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """H and y of Caccia eqs 16-19 for one run (θ = [m_ξ, m_ξ ξ₀ + k χ₀, b]).

    ξ is the SG derivative of the position, I = ∫ ξ|ξ| (trapezoid), ϕ = ∫ η φⁿ summed exactly
    for a zero-order-hold input (sample k held over [t_k, t_k+1)). The position is taken
    relative to its first sample (χ₀ is absorbed in the second parameter anyway). With an
    actuator lag, ``force`` is the lagged nominal force and ``force_neg`` its lagged negative
    part (:func:`~nnid.datasets.arrays.force_arrays`): η acts before the lag (eq. 3).
    ``angle``: the position is an attitude angle (p q r), unwrapped first
    (:func:`~nnid.datasets.preprocess.unwrap_finite`): readers keep it wrapped at ±π.
    """
    t = np.asarray(t, np.float64) - float(t[0])
    chi = np.asarray(position, np.float64)
    if angle:  # a wrap's 2π step entered ξ and the k χ term of y as motion
        chi = unwrap_finite(chi)
    chi = chi - float(chi[0])
    force = np.asarray(force, np.float64)
    dt = _sample_interval(t, np.zeros(max(t.size - 1, 0), bool), "the sinusoid run", False)[0]
    window = savgol_window(velocity_window, 1.0 / dt, velocity_order, "velocity_window")
    if chi.size <= window:
        raise NnidInputError(
            f"the sinusoid run has {chi.size} samples, too few for the Savitzky-Golay window "
            f"of {window}",
            field="sinusoid",
        )
    xi = savgol_interp(chi, window, velocity_order, 1, dt)
    effective = apply_installation(force, eta_pos, eta_neg, force_neg)
    varphi = np.r_[0.0, np.cumsum(effective[:-1] * np.diff(t))]
    integral = cumulative_trapezoid(xi * np.abs(xi), t, initial=0.0)
    y = varphi - k_linear * chi - k_quadratic * integral
    h = np.stack([xi, -np.ones_like(t), -t], 1)
    return h, y, ["m", "m*xi0+k*chi0", "b"]


# --- inputs for a force profile --------------------------------------------------------------


def force_to_commands(vehicle, dof: str, force: np.ndarray) -> np.ndarray:
    """Inputs ``[N, n_channels]`` that produce the nominal generalized force ``force`` in ``dof``
    (zero elsewhere): minimum-norm thrusts B# e_ξ φ (Caccia L211, the "all" modes of Table I),
    then each thrust curve inverted on its monotone branches: from each command limit inwards
    as far as the thrust keeps rising (:func:`_monotone_branch`). Weiss eq. 10, sign(c)·(0.0684
    − 0.03366|c| + 0.006736c²), falls over 0 < |c| < 2.5 (its extremum nearest zero) and
    rises beyond: the branch beyond is the one a bigger force needs, and thrust below the
    extremum's 0.026 N (other than 0, at c = 0) it cannot make; such a thrust is flown at the
    nearest it makes, and said. A force beyond a curve's reach is refused (the log would not
    fly the design it reports). A vehicle without thrusters takes the force itself."""
    act = Actuation(vehicle)
    force = np.asarray(force, np.float64)
    k = DOFS.index(dof)
    if not act.thrusters:
        out = np.zeros((force.size, 6))
        out[:, k] = force
        return out
    share = np.linalg.pinv(act.matrix)[:, k]  # thrust per unit force, [n_thrusters]
    out = np.zeros((force.size, len(act.channels)))
    for j, (thruster, curve) in enumerate(zip(act.thrusters, act.curves, strict=True)):
        if abs(share[j]) < 1e-12:
            continue
        lo = -1e3 if thruster.cmd_min is None else thruster.cmd_min
        hi = 1e3 if thruster.cmd_max is None else thruster.cmd_max
        branches = _monotone_branch(np.linspace(lo, hi, _GRID), curve)
        if branches is None:
            raise NnidInputError(
                f"the thrust curve of thruster '{thruster.name}' is not monotone over commands "
                f"{lo:g} to {hi:g}, and not of the shape sign(c)·g(|c|) whose dip around 0 "
                "the design can fly beyond (Weiss eq. 10): give a curve that rises with the "
                "command, or command limits inside its rising part",
                field="thrusters",
            )
        grid, thrust = branches
        asked = share[j] * force
        beyond = (asked < thrust[0]) | (asked > thrust[-1])
        if beyond.any():
            worst = int(np.argmax(np.abs(asked) * beyond))
            raise NnidInputError(
                f"the {dof} force profile asks thruster '{thruster.name}' for "
                f"{asked[worst]:.4g} N (at sample {worst}, force {force[worst]:.4g}); its "
                f"thrust curve reaches {thrust[0]:.4g} to {thrust[-1]:.4g} N over commands "
                f"{lo:g} to {hi:g}: lower the force (the sinusoid's offset and amplitude, or "
                "the validation run's fraction)",
                field="force",
            )
        # a thrust between two branches (a gap the curve cannot make): the nearer end
        step = (hi - lo) / (_GRID - 1)
        jumps = np.diff(grid) > 2.0 * step
        at = np.clip(np.searchsorted(thrust, asked), 1, thrust.size - 1)
        gap = jumps[at - 1]
        near = np.where(asked - thrust[at - 1] <= thrust[at] - asked, at - 1, at)
        out[:, j] = np.where(gap, grid[near], np.interp(asked, thrust, grid))
        off = np.where(gap, np.abs(curve(out[:, j]) - asked), 0.0)
        if off.max() > 0:
            skipped = " and ".join(
                f"{thrust[i]:.3g} to {thrust[i + 1]:.3g} N" for i in np.flatnonzero(jumps)
            )
            warnings.warn(
                f"thruster '{thruster.name}' makes no thrust between {skipped} (its curve "
                f"turns there): {int((off > 0).sum())} samples of the {dof} force profile "
                f"were flown at the nearest thrust it makes, up to {off.max():.3g} N from "
                "the design",
                UserWarning,
                stacklevel=2,
            )
    return out


#: commands on which a thrust curve is tabulated for its inversion
_GRID = 200_001


def _monotone_branch(grid: np.ndarray, curve) -> tuple[np.ndarray, np.ndarray] | None:
    """The commands of ``grid`` (ascending) on which ``curve`` is inverted, and their thrusts
    (non-decreasing): from each end of the grid inwards while the thrust keeps rising, and the
    command 0 between them where its thrust lies between the two branches' (a curve
    sign(c)·g(|c|) makes 0 there). A monotone curve is all of its grid. None for a curve of
    another shape: one whose falls do not lie between a negative and a positive rising branch
    (a curve that rolls over at its limits would keep only the limits), or whose branches
    together do not rise (a table with a dip away from 0)."""
    thrust = curve(grid)
    falls = np.flatnonzero(np.diff(thrust) < 0)
    if not falls.size:
        return grid, thrust
    low, high = slice(0, falls[0] + 1), slice(falls[-1] + 1, grid.size)
    if grid[low].size < 2 or grid[high].size < 2 or not grid[low][-1] < 0.0 < grid[high][0]:
        return None
    cmds, made = [grid[low]], [thrust[low]]
    zero = float(curve(np.zeros(1))[0])
    if thrust[low][-1] <= zero <= thrust[high][0]:
        cmds.append(np.zeros(1))
        made.append(np.array([zero]))
    cmds, made = np.concatenate([*cmds, grid[high]]), np.concatenate([*made, thrust[high]])
    return (cmds, made) if np.all(np.diff(made) >= 0) else None


# --- the trainer -----------------------------------------------------------------------------


def _combine(parts: Sequence[Estimate], names: Sequence[str] | None = None) -> Estimate:
    """Block-diagonal union of estimates (the steps' covariances are not cross-correlated),
    with the parts' excitation verdicts (:func:`~nnid.evaluation.persistence.combined_excitation`)
    under the union's names: the reports show them beside each parameter."""
    names = list(names) if names is not None else [n for p in parts for n in p.names]
    theta = np.concatenate([p.theta for p in parts])
    cov = np.zeros((theta.size, theta.size))
    checks = []
    k = 0
    for p in parts:
        n = p.theta.size
        cov[k : k + n, k : k + n] = p.cov
        checks.append((names[k : k + n], p.excitation))
        k += n
    return Estimate(
        names,
        theta,
        cov,
        parts[0].sigma2,
        sum(p.n_obs for p in parts),
        combined_excitation(checks, names),
    )


class CacciaTwoStep:
    """Caccia's two-step identification of one DOF (module docstring; eqs 7-20).

    Use :meth:`fit_logs` with the steady-state campaign log and the sinusoid log, or the
    steps one by one: :meth:`fit_steady`, :meth:`design_sinusoid`, :meth:`fit_inertia`. The
    trainer protocol :meth:`fit` takes a structure with a ``vehicle`` and the arrays of
    :func:`nnid.models.parametric.log_arrays` (``{"steady": …, "sinusoid": …}``); the unknowns
    are Caccia's fixed set, not the structure's, because the procedure identifies exactly
    them (drag, restoring/disturbance, installation, then inertia) from two dedicated runs.

    Parameters: ``dof`` (u v w p q r); ``reference`` the (mode, direction) groups with η ≡ 1
    (default downward/positive thrust of the only mode, eq. 20); ``mode_column`` a log
    column naming each sample's thrust mapping mode; ``force_eta_one`` fixes η = 1 for every
    direction (Caccia Fig. 6); ``terms`` the drag terms; ``settings`` maps experiment names to
    Caccia's weight-setting index i (default: order of appearance, 0, 1, …); the plateau rule
    (``settle_window`` s, ``settle_order``, ``settle_accel`` in units of the position per s²,
    ``min_plateau`` s, ``speed``); ``weighting`` of the step-1 rows; the step-2 SG velocity
    (``velocity_window`` s, ``velocity_order``) and ``correlated``.
    """

    kind = "caccia"

    def __init__(
        self,
        dof: str = "w",
        reference: Sequence[tuple[str, str]] = (("", "pos"),),
        mode_column: str | None = None,
        force_eta_one: bool = False,
        terms: Sequence[str] = ("linear", "quadratic"),
        settings: Mapping[str, int] | None = None,
        settle_window: float = 10.0,
        settle_order: int = 2,
        settle_accel: float = 2e-3,
        min_plateau: float = 10.0,
        speed: Literal["slope", "mean", "asymptote"] = "asymptote",
        velocity_window: float = 5.0,
        velocity_order: int = 4,
        correlated: bool = True,
        weighting: Literal["none", "speed"] = "speed",
    ) -> None:
        if dof not in DOFS:
            raise ValueError(f"'{dof}' is not a DOF; expected one of {' '.join(DOFS)}")
        self.dof = dof
        self.reference = tuple(tuple(r) for r in reference)
        self.mode_column = mode_column
        self.force_eta_one = force_eta_one
        self.terms = tuple(terms)
        self.settings = dict(settings) if settings is not None else None
        self.settle_window = settle_window
        self.settle_order = settle_order
        self.settle_accel = settle_accel
        self.min_plateau = min_plateau
        self.speed = speed
        self.velocity_window = velocity_window
        self.velocity_order = velocity_order
        self.correlated = correlated
        self.weighting = weighting
        self.plateaus_: list[Plateau] = []
        self.steady_: Estimate | None = None
        self.inertia_: Estimate | None = None
        self.estimate_: Estimate | None = None

    # -- names ----------------------------------------------------------------------------------
    @property
    def force_name(self) -> str:
        return FORCES[DOFS.index(self.dof)]

    @property
    def angular(self) -> bool:
        """Whether the DOF's position χ is an attitude angle (p q r), kept wrapped by readers."""
        return POSITION_OF[self.dof] in ANGLES

    def vehicle_names(self, names: Sequence[str]) -> list[str]:
        """Caccia-signed step-1 names -> vehicle-file names (module docstring)."""
        k1, k2, nu, dnu = caccia_names(self.dof)
        f, d = self.force_name, self.dof
        heave = d == "w"
        table = {
            k1: f"{f}:{d}",
            k2: f"{f}:{d}*abs({d})",
            nu: "weight_minus_buoyancy" if heave else f"external_bias.{d}",
            dnu: "delta_weight" if heave else f"delta_bias.{d}",
        }
        return [table.get(n, n) for n in names]

    def to_vehicle_signs(self, est: Estimate) -> Estimate:
        """Caccia's positive k -> Fossen coefficients −k (covariance transformed alike), the
        excitation verdicts renamed with them (under Caccia's names they named no parameter)."""
        k1, k2, _, _ = caccia_names(self.dof)
        sign = np.array([-1.0 if n in (k1, k2) else 1.0 for n in est.names])
        names = self.vehicle_names(est.names)
        return Estimate(
            names,
            est.theta * sign,
            est.cov * np.outer(sign, sign),
            est.sigma2,
            est.n_obs,
            None
            if est.excitation is None
            else est.excitation.renamed(dict(zip(est.names, names, strict=True))),
        )

    def _caccia_value(self, name: str, default: float = 0.0) -> float:
        if self.steady_ is None:
            raise RuntimeError("fit the steady-state step first")
        if name in self.steady_.names:
            return float(self.steady_.theta[self.steady_.names.index(name)])
        return default

    def eta(self, direction: str, mode: str = "") -> float:
        """Identified (or reference, 1) installation coefficient of a mode and direction."""
        return self._caccia_value(eta_name(self.dof, mode, direction), 1.0)

    # -- step 1 ---------------------------------------------------------------------------------
    def steady_arrays(
        self,
        t: np.ndarray,
        position: np.ndarray,
        force: np.ndarray,
        experiment: np.ndarray,
        names: Sequence[str] | None = None,
        modes: np.ndarray | None = None,
        runs: Sequence[str] | None = None,
    ) -> Estimate:
        """Step 1 on arrays (position χ, nominal force φⁿ_ξ, experiment codes 0, 1, …).
        ``runs``: the run of each code (``experiment_runs`` of
        :func:`nnid.datasets.arrays.motion_arrays`): the pieces a gap cut one run into are one
        weight setting, keyed in :attr:`settings` by the run's name. Returns the Caccia-signed
        estimate (also in :attr:`steady_`)."""
        settings = None
        if runs is not None:
            runs = [str(r) for r in runs]
            names = [str(n) for n in names] if names is not None else runs
            if list(runs) != list(names):  # a run's pieces share its setting: eq. 20's i
                settings = pd.factorize(np.asarray(runs, dtype=object))[0].tolist()
        keys = runs if runs is not None else names
        if self.settings is not None:
            if keys is None:
                raise ValueError("settings by experiment name need the experiment names")
            missing = list(dict.fromkeys(n for n in keys if n not in self.settings))
            if missing:
                raise NnidInputError(
                    f"no weight setting for experiments {missing}", field="steady_state.settings"
                )
            settings = [self.settings[n] for n in keys]
        self.plateaus_ = find_plateaus(
            t,
            position,
            force,
            experiment,
            names,
            settings,
            modes,
            self.settle_window,
            self.settle_order,
            self.settle_accel,
            self.min_plateau,
            self.speed,
            self.angular,
        )
        h, y, pnames = steady_state_regression(
            self.plateaus_, self.dof, self.reference, self.force_eta_one, self.terms
        )
        est = solve_least_squares(h, y, names=pnames)
        if self.weighting == "speed":
            est = solve_least_squares(h, y, self._row_weights(est), pnames)
        self.steady_ = est
        return self.steady_

    def fit_steady(self, log: pd.DataFrame, vehicle) -> Estimate:
        """Step 1 (eqs 7-10, 20) on the steady-state campaign log; Caccia-signed estimate."""
        arrays = self._log_arrays(log, vehicle)
        modes = None
        if self.mode_column is not None:
            if self.mode_column not in log:
                raise NnidInputError(f"no mode column '{self.mode_column}'", source="log")
            modes = log[self.mode_column].astype(str).to_numpy()
        return self._steady_from(arrays, modes)

    def _steady_from(self, arrays: Mapping[str, Any], modes: np.ndarray | None) -> Estimate:
        k = DOFS.index(self.dof)
        names = arrays.get("experiment_names")
        return self.steady_arrays(
            arrays["t"],
            arrays["eta"][:, k],
            arrays["tau"][:, k],
            arrays["experiment"],
            names,
            modes,
            arrays.get("experiment_runs"),
        )

    def _log_arrays(self, log: pd.DataFrame, vehicle) -> dict[str, Any]:
        column = POSITION_OF[self.dof]
        if column not in log:
            raise NnidInputError(
                f"no column '{column}': Caccia's procedure needs the position of "
                f"DOF '{self.dof}' (velocities are estimated from it)",
                source="log",
            )
        arrays = log_arrays(log, vehicle)
        arrays["experiment_names"] = (
            list(pd.unique(log["experiment"])) if "experiment" in log else ["0"]
        )
        return arrays

    def _row_weights(self, first: Estimate) -> np.ndarray:
        """1 / var of each eq.-7 row from its speed's standard error: a speed error δξ moves
        the row by k_L δξ, k_L = k + 2 k₂|ξ| from the first (ordinary) fit."""
        k1, k2, _, _ = caccia_names(self.dof)
        th = dict(zip(first.names, np.nan_to_num(first.theta), strict=True))
        xi = np.array([p.speed for p in self.plateaus_])
        sd = np.array([p.speed_std for p in self.plateaus_])
        k_l = np.abs(th.get(k1, 0.0) + 2 * th.get(k2, 0.0) * np.abs(xi))
        var = (k_l * sd) ** 2
        return 1.0 / np.maximum(var, 1e-6 * max(float(np.median(var)), 1e-300))

    def residuals(self) -> np.ndarray:
        """Step-1 residuals y − Hθ̂ of eq. 7 per plateau, in force units (N for heave)."""
        if self.steady_ is None:
            raise RuntimeError("fit the steady-state step first")
        h, y, _ = steady_state_regression(
            self.plateaus_, self.dof, self.reference, self.force_eta_one, self.terms
        )
        return y - h @ np.nan_to_num(self.steady_.theta)

    # -- design ---------------------------------------------------------------------------------
    def design_sinusoid(
        self,
        offset: float,
        amplitude: float,
        prior_inertia: float,
        duration: float,
        start: float = 0.0,
    ) -> DOptimalSine:
        """Caccia eqs 13-15 with the step-1 drag: the d-optimal sinusoid on the force channel,
        ω_opt = 1/(√3 t_c) for the prior inertia (Caccia: m_air × (1.1 … 2), L153)."""
        k1, k2, _, _ = caccia_names(self.dof)
        eta = self.eta("pos" if offset >= 0 else "neg")
        return DOptimalSine(
            channel=self.force_name,
            start=start,
            offset=offset,
            amplitude=amplitude,
            inertia=prior_inertia,
            k_linear=max(self._caccia_value(k1), 0.0),
            k_quadratic=max(self._caccia_value(k2), 0.0),
            eta=eta,
            duration=duration,
        )

    # -- step 2 ---------------------------------------------------------------------------------
    def inertia_arrays(
        self,
        t: np.ndarray,
        position: np.ndarray,
        force: np.ndarray,
        force_neg: np.ndarray | None = None,
    ) -> Estimate:
        """Step 2 (eqs 16-19) on one run; Caccia's θ = [m_ξ, m_ξ ξ₀ + k χ₀, b] (also in
        :attr:`inertia_`). ``force_neg``: the lagged negative part of a lagged ``force``
        (:func:`integrated_regression`)."""
        k1, k2, _, _ = caccia_names(self.dof)
        h, y, names = integrated_regression(
            t,
            position,
            force,
            self._caccia_value(k1),
            self._caccia_value(k2),
            self.eta("pos"),
            self.eta("neg"),
            self.velocity_window,
            self.velocity_order,
            force_neg,
            self.angular,
        )
        est = solve_least_squares(h, y, names=names)
        if self.correlated:
            reg = Regression(h, y, names, (self.dof,), y.size)
            est.cov = est.cov * correlation_time(reg.residuals(est.theta))
        self.inertia_ = est
        return est

    def fit_inertia(self, log: pd.DataFrame, vehicle) -> Estimate:
        """Step 2 on the sinusoid log (one experiment); Caccia-signed estimate."""
        return self._inertia_from(self._log_arrays(log, vehicle))

    def _inertia_from(self, arrays: Mapping[str, Any]) -> Estimate:
        k = DOFS.index(self.dof)
        _one_sinusoid_run(arrays)
        neg = arrays.get("tau_neg")
        return self.inertia_arrays(
            arrays["t"],
            arrays["eta"][:, k],
            arrays["tau"][:, k],
            None if neg is None else neg[:, k],
        )

    # -- both -----------------------------------------------------------------------------------
    def rigid_inertia(self, vehicle) -> float:
        """Rigid-body mass (u v w) or moment of inertia (p q r) of the vehicle file."""
        k = DOFS.index(self.dof)
        return float(vehicle.mass) if k < 3 else float(vehicle.inertia_matrix()[k - 3, k - 3])

    def fit_logs(
        self, steady: pd.DataFrame, vehicle, sinusoid: pd.DataFrame | None = None
    ) -> Estimate:
        """Both steps; the estimate in vehicle-file names and Fossen signs (module docstring),
        the added mass ``"Z_wdot" = −(m_ξ − m)`` last when a sinusoid log is given."""
        self.fit_steady(steady, vehicle)
        if sinusoid is not None:
            self.fit_inertia(sinusoid, vehicle)
        return self._finish(vehicle)

    def fit(self, structure, data: Mapping[str, Any], progress: Progress | None = None) -> Estimate:
        """Trainer protocol: ``structure.vehicle`` and ``data`` = ``{"steady": log_arrays(…),
        "sinusoid": log_arrays(…)}`` (sinusoid optional), or the steady arrays alone. The
        arrays' pose column of the DOF must be the measured position. Mode labels, if any,
        come as ``data["steady"]["mode"]``."""
        vehicle = structure.vehicle
        steady = data["steady"] if "steady" in data else data
        self._steady_from(steady, steady.get("mode"))
        if "sinusoid" in data and data["sinusoid"] is not None:
            self._inertia_from(data["sinusoid"])
        (progress or silent)(1, 1, "Caccia two-step")
        return self._finish(vehicle)

    def _finish(self, vehicle) -> Estimate:
        assert self.steady_ is not None
        parts = [self.to_vehicle_signs(self.steady_)]
        if self.inertia_ is not None:
            m = self.inertia_
            added = f"{self.force_name}_{self.dof}dot"
            rigid = self.rigid_inertia(vehicle)
            parts.append(
                Estimate(
                    [added],
                    np.array([-(m.theta[0] - rigid)]),
                    m.cov[:1, :1].copy(),
                    m.sigma2,
                    m.n_obs,
                    # m_ξ's verdict is the added mass's (−(m_ξ − m), m known)
                    None if m.excitation is None else m.excitation.renamed({m.names[0]: added}),
                )
            )
        self.estimate_ = _combine(parts)
        self.estimate_.dof_sigma2 = {"steady_state": self.steady_.sigma2}
        if self.inertia_ is not None:
            self.estimate_.dof_sigma2["inertia"] = self.inertia_.sigma2
        return self.estimate_

    def describe(self) -> str:
        """The estimate with σ̂ and percentile errors (51.02 % rule flagged)."""
        if self.estimate_ is None:
            return "not fitted"
        est = self.estimate_
        lines = [
            f"Caccia two-step identification of DOF '{self.dof}' ({len(self.plateaus_)} plateaus):"
        ]
        for name, v, s, pe, ok in zip(
            est.names, est.theta, est.stderr, est.percentile_error, est.significant, strict=True
        ):
            flag = "" if ok else "  (insignificant at 95 %, > 51.02 %)"
            lines.append(f"  {name:>22s} = {v:.6g} ± {s:.2g} ({pe:.1f} %){flag}")
        if self.inertia_ is not None:
            m, s = self.inertia_.theta[0], self.inertia_.stderr[0]
            lines.append(f"  {'m_' + self.dof + ' (total)':>22s} = {m:.6g} ± {s:.2g}")
        return "\n".join(lines)


# --- the campaign ---------------------------------------------------------------------------


def caccia_campaign(
    campaign, vehicle, trainer: CacciaTwoStep, sinusoid, validation=None
) -> tuple[pd.DataFrame, DOptimalSine]:
    """Caccia's campaign flown end to end (section III), as one log: the steady-state runs of
    ``campaign`` (a :class:`nnid.config.SimulateConfig`), step 1 fitted on them, the d-optimal
    sinusoid designed from that drag (``sinusoid``: offset, amplitude, prior inertia or added
    fraction, duration, seed, measurement) and flown (experiment "sinusoid"), and with
    ``validation`` a held-out PRBS run on the same DOF (fresh noise; its experiment name,
    duration, hold, amplitude fraction and seed). Returns the log and the design."""
    steady_log = simulate_config(campaign, vehicle)
    trainer.fit_steady(steady_log, vehicle)
    prior = sinusoid.prior_inertia or trainer.rigid_inertia(vehicle) * (
        1 + sinusoid.prior_added_fraction
    )
    design = trainer.design_sinusoid(sinusoid.offset, sinusoid.amplitude, prior, sinusoid.duration)
    effects = [(e.name, e.value) for e in campaign.effects]
    sinusoid_log = simulate_sinusoid(
        vehicle,
        design,
        trainer.dof,
        campaign.dt,
        substeps=campaign.substeps,
        measurement=sinusoid.measurement or campaign.measurement,
        seed=sinusoid.seed,
        effects=effects,
    )
    logs = [steady_log, sinusoid_log]
    if validation is not None:
        t = np.arange(0.0, validation.duration, campaign.dt)
        rms_force = float(np.std(steady_log.filter(like="cmd_").to_numpy())) or 1.0
        amp = validation.fraction * max(abs(sinusoid.offset), sinusoid.amplitude, rms_force)
        prbs = PRBS(
            channel="X",
            amplitude=amp,
            hold=validation.hold,
            duration=t[-1] + campaign.dt,
            seed=validation.seed,
        )
        logs.append(
            simulate(
                vehicle,
                force_to_commands(vehicle, trainer.dof, prbs(t)),
                campaign.dt,
                substeps=campaign.substeps,
                effects=effects,
                measurement=campaign.measurement,
                seed=campaign.seed + 999,
                experiment=validation.experiment,
            )
        )
    return pd.concat(logs, ignore_index=True), design


def simulate_sinusoid(
    vehicle,
    design: DOptimalSine,
    dof: str,
    dt: float,
    substeps: int = 10,
    measurement: Measurement | None = None,
    seed: int = 0,
    effects: Sequence[tuple[str, float]] = (),
) -> pd.DataFrame:
    """A log of the d-optimal sinusoid run: the force profile through :func:`force_to_commands`."""
    t = np.arange(round(design.end() / dt)) * dt  # every sample inside the sinusoid
    inputs = force_to_commands(vehicle, dof, design(t))
    return simulate(
        vehicle,
        inputs,
        dt,
        effects=effects,
        substeps=substeps,
        measurement=measurement,
        seed=seed,
        experiment="sinusoid",
    )


__all__ = [
    "POSITION_OF",
    "CacciaTwoStep",
    "Plateau",
    "caccia_campaign",
    "find_plateaus",
    "force_to_commands",
    "integrated_regression",
    "simulate_sinusoid",
    "steady_state_regression",
]
