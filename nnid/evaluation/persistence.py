"""Persistence of excitation of a regression (Weiss eqs 93-98).

A regressor Φ is persistently exciting when α₁ I ≤ (1/N) ΦᵀΦ ≤ α₂ I for some α₁ > 0 (eq. 95):
every parameter direction is seen. The report gives the rank and condition number of ΦᵀΦ, the
smallest singular value per parameter group, and names the parameters that the data does not
excite (a regressor column that is zero) or cannot separate (it lies in a near-null direction).
Columns are scaled to unit RMS first, so the verdict does not depend on units.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class ExcitationReport:
    n_samples: int
    n_params: int
    rank: int
    condition: float
    singular_values: list[float]
    group_min_singular: dict[str, float]
    unexcited: list[str]
    collinear: list[str]
    warnings: list[str] = field(default_factory=list)

    @property
    def persistent(self) -> bool:
        return self.rank == self.n_params and not self.unexcited


def excitation_report(
    phi: np.ndarray, names: list[str], groups: dict[str, list[str]] | None = None, tol: float = 1e-6
) -> ExcitationReport:
    """Diagnose the regressor ``phi`` ``[N, P]`` whose columns belong to parameters ``names``."""
    phi = np.asarray(phi, dtype=np.float64)
    if phi.ndim != 2 or phi.shape[1] != len(names):
        raise ValueError("phi must be [N, len(names)]")
    n, p = phi.shape
    rms = np.sqrt(np.mean(phi**2, axis=0))
    scale = rms.max() if rms.size and rms.max() > 0 else 1.0
    unexcited = [names[j] for j in range(p) if rms[j] <= tol * scale]
    live = rms > tol * scale
    normed = np.where(live, phi / np.where(live, rms, 1.0), 0.0) / np.sqrt(max(n, 1))
    sv = np.linalg.svd(normed, compute_uv=False) if p else np.array([])
    rank = int(np.sum(sv > tol * (sv[0] if sv.size else 1.0)))
    condition = float((sv[0] / sv[-1]) ** 2) if sv.size and sv[-1] > 0 else float("inf")
    collinear: list[str] = []
    if live.sum() > 1:
        _, s_live, vt = np.linalg.svd(normed[:, live], full_matrices=False)
        live_names = [nm for nm, keep in zip(names, live, strict=True) if keep]
        for k in np.flatnonzero(s_live < np.sqrt(tol) * s_live[0]):
            collinear += [live_names[j] for j in np.flatnonzero(np.abs(vt[k]) > 0.3)]
        collinear = sorted(set(collinear), key=live_names.index)
    group_min = {}
    for g, members in (groups or {}).items():
        cols = [names.index(m) for m in members]
        s = np.linalg.svd(normed[:, cols], compute_uv=False)
        group_min[g] = float(s.min()) if s.size else 0.0
    warnings = []
    if unexcited:
        warnings.append(f"not excited by this data (zero regressor): {', '.join(unexcited)}")
    if collinear:
        warnings.append(
            f"not separable from each other (collinear regressors): {', '.join(collinear)}"
        )
    if rank < p and not warnings:
        warnings.append(f"the regressor has rank {rank} < {p} parameters")
    return ExcitationReport(
        n, p, rank, condition, [float(s) for s in sv], group_min, unexcited, collinear, warnings
    )
