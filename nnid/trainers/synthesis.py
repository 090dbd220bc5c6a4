"""Viscous-model synthesis (McCarter ch. 4, eqs 4.4-4.27): the fitting algorithms.

The residual force (McCarter eq. 4.4)

    τ̄(k) = M ν̇(k) + C(ν(k)) ν(k) − g(η(k)) − τ_U(k)

is what the log shows of the viscous force once the rigid body, added mass, restoring forces and
the actuation are taken out; a viscous model K ξ(ν) (eq. 4.6) is then fitted to it. With a mask
(McCarter's M_k, eq. 4.15) choosing which of the basis terms each force ``X Y Z K M N`` uses, the
stacked problem (eqs 4.16-4.20)

    σ̃ = Ξ κ − σ̄,   Ξ = (I_6 ⊗ ξ_*ᵀ) M_kᵀ,   κ = M_k vec(Kᵀ)

is block diagonal, so it separates into one least-squares problem per force (eq. 4.22). The
alternative costs of eqs 4.23-4.27 (MAE, MSE, RMS and McCarter's "MAD", the sum over axes of the
median absolute residual) are minimised by Nelder-Mead started from the least-squares solution.
Every one of them is a sum (or a monotone function of a sum) of per-force terms, so minimising
force by force gives the joint minimum while keeping each simplex small: Nelder-Mead over all
216 McFarland coefficients at once would take hundreds of thousands of evaluations and rarely
converges; per force it is 36 parameters at most (still slow: use it on small masks).

The model error is McCarter's eq. 4.25, J = RMS of the force residual over all six axes, and J0
the RMS of the force series itself (J at κ = 0), both also available per force. The model that
computes τ̄ and ξ(ν) from a log and uses these fits is :class:`nnid.models.synthesis.SynthesisModel`.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.optimize import minimize

from nnid.evaluation.persistence import typical_size
from nnid.physics.damping_library import LIBRARY, canonical_term, mask_terms
from nnid.physics.dofs import FORCES
from nnid.trainers.least_squares import LeastSquares
from nnid.trainers.regression import Regression

Loss = Literal["mae", "mse", "rms", "mad"]
LOSSES: tuple[str, ...] = ("mae", "mse", "rms", "mad")
MaskSpec = str | Mapping[str, Sequence[str]] | np.ndarray


def mask_matrix(mask: MaskSpec, terms: Sequence[str]) -> np.ndarray:
    """McCarter's mask M_k (eq. 4.15) as a boolean ``[6, len(terms)]`` (row = force X..N).

    ``mask`` is a named model (:func:`mask_terms`), a ``{force: terms}`` mapping or already a
    boolean array."""
    if isinstance(mask, np.ndarray):
        out = np.asarray(mask, dtype=bool)
        if out.shape != (6, len(terms)):
            raise ValueError(f"mask must have shape (6, {len(terms)}), got {out.shape}")
        return out
    spec = mask_terms(mask) if isinstance(mask, str) else mask
    index = {canonical_term(t): j for j, t in enumerate(terms)}
    out = np.zeros((6, len(terms)), dtype=bool)
    for force, names in spec.items():
        for name in names:
            term = canonical_term(name)
            if term not in index:
                raise ValueError(f"mask term '{name}' of force {force} is not among the terms")
            out[FORCES.index(force), index[term]] = True
    return out


def mask_term_list(mask: str | Mapping[str, Sequence[str]]) -> list[str]:
    """The terms a mask uses, in McCarter's basis order (C.7), others after."""
    spec = mask_terms(mask) if isinstance(mask, str) else mask
    used = {canonical_term(t) for names in spec.values() for t in names}
    ordered = [t for t in LIBRARY if t in used]
    return ordered + sorted(used - set(ordered))


@dataclass
class SynthesisFit:
    """A fitted coefficient matrix K ``[6, n_terms]`` (zero off the mask) with its standard
    errors (NaN off the mask and for Nelder-Mead fits), the mask itself, and the entries of
    the mask the fit left unidentified (``unidentified``, boolean like the mask; none when not
    given): no estimate, K holds 0 there (see :func:`masked_least_squares`)."""

    coefficients: np.ndarray
    stderr: np.ndarray
    mask: np.ndarray
    unidentified: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.unidentified is None:
            self.unidentified = np.zeros(np.shape(self.mask), dtype=bool)

    def predict(self, xi: np.ndarray) -> np.ndarray:
        """τ̂ = K ξ(ν) per sample ``[N, 6]`` (eq. 4.6)."""
        return xi @ self.coefficients.T

    @property
    def kappa(self) -> np.ndarray:
        """κ = M_k vec(Kᵀ) (eq. 4.19): the masked coefficients, force-major."""
        return self.coefficients[self.mask]


def masked_least_squares(
    xi: np.ndarray,
    tau_bar: np.ndarray,
    mask: np.ndarray,
    terms: Sequence[str] | None = None,
    outputs: Sequence[str] = FORCES,
    floors: np.ndarray | None = None,
) -> SynthesisFit:
    """Least squares of the synthesis model σ̃ = Ξ κ − σ̄ (eqs 4.20, 4.22), one force at a time
    (Ξ is block diagonal). ``xi`` ``[N, n_terms]``, ``tau_bar`` ``[N, 6]``, ``mask`` boolean
    ``[6, n_terms]``; ``terms`` and ``outputs`` only name the coefficients in warnings.
    ``floors`` ``[n_terms]``: each term's floor of the rounding rule where not NaN
    (:func:`~nnid.evaluation.persistence.library_floors`), else it is judged against Ξ's typical
    regressor. Standard errors come from :class:`LeastSquares` (widened for the residual's
    autocorrelation, as smoothed accelerations make neighbouring samples dependent).
    """
    mask = np.asarray(mask, dtype=bool)
    k = np.zeros(mask.shape)
    se = np.full(mask.shape, np.nan)
    unidentified = np.zeros(mask.shape, dtype=bool)
    solver = LeastSquares(weighting="none")
    # the forces' problems are blocks of one (Ξ, eq. 4.20): a column of rounding is zero
    # against Ξ's typical regressor, though its own block (X:u alone) has no other to compare;
    # typical, not largest: an (η − 1) term at U = 0 (1e12) would make every other one "zero"
    used = xi[:, mask.any(0)]
    reference = typical_size(used[np.isfinite(used).all(1)])
    for f in range(6):
        cols = np.flatnonzero(mask[f])
        if cols.size == 0:
            continue
        names = [f"{outputs[f]}:{terms[j] if terms is not None else j}" for j in cols]
        own = None if floors is None else np.asarray(floors, dtype=np.float64)[cols]
        motion = None if own is None else (lambda own=own: own)
        reg = Regression(xi[:, cols], tau_bar[:, f], names, ("u",), tau_bar.shape[0], motion)
        est = solver.solve(reg, reference)
        # an unidentified term (a zero regressor: NaN, which solve names) at 0, not at the
        # vehicle file's value as a Fossen model's (simulated_values): K replaces the file's
        # damping wholesale (McCarter eq. 4.6), so a file coefficient of another basis would
        # mix two damping models; 0 is the term absent, as off the mask. Which ones is kept
        # (unidentified): a 0 there is no estimate, and the model says so (its params)
        k[f, cols] = np.nan_to_num(est.theta)
        unidentified[f, cols] = ~np.isfinite(est.theta)
        se[f, cols] = est.stderr  # NaN for a term of a collinear group
    return SynthesisFit(k, se, mask, unidentified)


def loss_value(residual: np.ndarray, loss: Loss) -> float:
    """McCarter's costs on a residual ``[N]`` or ``[N, 6]``: MAE (eq. 4.23), MSE (4.24), RMS
    (4.25) and "MAD" (4.26-4.27: the per-axis median of |τ̃| summed over the axes)."""
    r = np.asarray(residual, dtype=np.float64)
    if loss == "mae":
        return float(np.mean(np.abs(r)))
    if loss == "mse":
        return float(np.mean(r * r))
    if loss == "rms":
        return float(np.sqrt(np.mean(r * r)))
    if loss == "mad":
        r2 = r.reshape(r.shape[0], -1)
        return float(np.sum(np.median(np.abs(r2), axis=0)))
    raise ValueError(f"unknown loss '{loss}'; expected one of {', '.join(LOSSES)}")


def nelder_mead(
    xi: np.ndarray,
    tau_bar: np.ndarray,
    mask: np.ndarray,
    loss: Loss,
    start: SynthesisFit | None = None,
    forces: Sequence[str] = FORCES,
    max_iter_per_param: int = 400,
    tol: float = 1e-9,
    floors: np.ndarray | None = None,
    terms: Sequence[str] | None = None,
) -> SynthesisFit:
    """Minimise an eq. 4.23-4.27 cost by Nelder-Mead, force by force, from the least-squares
    solution (or ``start``). Each cost is a sum (or monotone in a sum) of per-force costs, so
    the per-force minima are the joint minimum. The search runs in coordinates where a unit step
    of a coefficient changes its force by one RMS unit of the force series, with an initial
    simplex of 10 % of that scale. Slow: the budget grows with the parameters per force
    (``max_iter_per_param``), so keep it to small masks or to the ``forces`` of interest.
    ``floors``: each term's floor of the rounding rule for the least-squares start
    (:func:`masked_least_squares`'s, unused with ``start``): the start the model's own solve
    gives, so that a term of rounding is unidentified and held at 0, not searched from a
    value fitted to rounding. ``terms``: the names of Ξ's columns, which the least-squares
    start's warnings name its coefficients by ("X:u", not "X:0"; unused with ``start``)."""
    if loss not in LOSSES:
        raise ValueError(f"unknown loss '{loss}'; expected one of {', '.join(LOSSES)}")
    mask = np.asarray(mask, dtype=bool)
    base = (
        start
        if start is not None
        else masked_least_squares(xi, tau_bar, mask, terms, floors=floors)
    )
    k = base.coefficients.copy()
    stopped: list[str] = []
    for force in forces:
        f = FORCES.index(force)
        # an unidentified term stays at 0: no cost reads it (a zero or left-out regressor),
        # and a flat direction of the simplex would carry it to a value the data never saw
        cols = np.flatnonzero(mask[f] & ~base.unidentified[f])
        if cols.size == 0:
            continue
        y = tau_bar[:, f]
        ok = np.isfinite(y) & np.isfinite(xi[:, cols]).all(1)
        a, y = xi[ok][:, cols], y[ok]
        col_rms = np.sqrt(np.mean(a * a, axis=0))
        col_rms[col_rms == 0] = 1.0
        y_rms = float(np.sqrt(np.mean(y * y))) or 1.0
        scale = col_rms / y_rms  # θ_scaled = θ * scale: a unit step = one RMS unit of force
        a_s = a / col_rms * y_rms

        def cost(theta_s: np.ndarray, a_s=a_s, y=y) -> float:
            return loss_value(a_s @ theta_s - y, loss)

        x0 = k[f, cols] * scale
        simplex = np.vstack([x0, x0 + 0.1 * np.eye(cols.size)])
        res = minimize(
            cost,
            x0,
            method="Nelder-Mead",
            options={
                "initial_simplex": simplex,
                "maxiter": max_iter_per_param * cols.size,
                "maxfev": 2 * max_iter_per_param * cols.size,
                "xatol": tol,
                "fatol": tol * y_rms,
                "adaptive": cols.size > 5,
            },
        )
        k[f, cols] = res.x / scale
        if not res.success:
            stopped.append(force)
    if stopped:
        warnings.warn(
            f"the Nelder-Mead search of the '{loss}' cost stopped at its iteration limit for "
            f"{', '.join(stopped)} (max_iter_per_param = {max_iter_per_param}): those "
            "coefficients are where it stopped, not a minimum",
            UserWarning,
            stacklevel=2,
        )
    return SynthesisFit(k, np.full(mask.shape, np.nan), mask, base.unidentified.copy())


def force_error(
    tau_bar: np.ndarray, tau_hat: np.ndarray, per_force: bool = False
) -> tuple[float, float] | tuple[np.ndarray, np.ndarray]:
    """(J, J0) of McCarter eq. 4.25: J the RMS of the force residual τ̂ − τ̄, J0 the RMS of the
    force series τ̄ (J at κ = 0). Combined over the six axes as McCarter does (forces and
    moments in one number) or, with ``per_force``, one pair per axis ``[6]``. Samples with a
    non-finite value are left out."""
    tau_bar = np.asarray(tau_bar, dtype=np.float64)
    res = np.asarray(tau_hat, dtype=np.float64) - tau_bar
    ok = np.isfinite(res).all(1)
    res, tau_bar = res[ok], tau_bar[ok]
    if per_force:
        return np.sqrt(np.mean(res * res, 0)), np.sqrt(np.mean(tau_bar * tau_bar, 0))
    return float(np.sqrt(np.mean(res * res))), float(np.sqrt(np.mean(tau_bar * tau_bar)))
