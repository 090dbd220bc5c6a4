"""Persistence of excitation of a regression (Weiss eqs 93-98).

A regressor Φ is persistently exciting when α₁ I ≤ (1/N) ΦᵀΦ ≤ α₂ I for some α₁ > 0 (eq. 95):
every parameter direction is seen. The report gives the rank and condition number of ΦᵀΦ, the
smallest singular value per parameter group, and names the parameters that the data does not
excite (a regressor column that is zero) or cannot separate (it lies in a near-null direction).
Columns are scaled to unit RMS first, so the verdict does not depend on units.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from nnid.serialization import exact_float, read_exact_float


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

    def as_state(self) -> dict:
        """The report as strict JSON data; the condition number of a singular ΦᵀΦ is inf,
        tagged so that it reads back inf (:func:`~nnid.serialization.exact_float`)."""
        return {**asdict(self), "condition": exact_float(self.condition)}

    @classmethod
    def from_state(cls, state: object) -> ExcitationReport:
        """Inverse of :meth:`as_state` after a JSON round trip, checked (TypeError): a file
        edited by hand is refused at loading, never a report that fails when read."""
        if not isinstance(state, dict):
            raise TypeError("the excitation report is not a mapping")

        def names(key: str) -> list[str]:
            value = state[key]
            if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
                raise TypeError(f"the excitation report's {key} is not a list of names")
            return list(value)

        def count(key: str) -> int:
            value = state[key]
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise TypeError(f"the excitation report's {key} is not a count: {value!r}")
            return value

        values, groups = state["singular_values"], state["group_min_singular"]
        if not isinstance(values, list) or not isinstance(groups, dict):
            raise TypeError("the excitation report's singular values are not numbers")
        what = "the excitation report's singular values"
        return cls(
            count("n_samples"),
            count("n_params"),
            count("rank"),
            read_exact_float(state["condition"], "the excitation report's condition"),
            [read_exact_float(v, what) for v in values],
            {str(k): read_exact_float(v, what) for k, v in groups.items()},
            names("unexcited"),
            names("collinear"),
            names("warnings"),
        )


def excitation_report(
    phi: np.ndarray,
    names: list[str],
    groups: dict[str, list[str]] | None = None,
    tol: float = 1e-6,
) -> ExcitationReport:
    """Diagnose the regressor ``phi`` ``[N, P]`` whose columns belong to parameters ``names``."""
    phi = np.asarray(phi, dtype=np.float64)
    if phi.ndim != 2 or phi.shape[1] != len(names):
        raise ValueError("phi must be [N, len(names)]")
    return excitation_from_gram(phi.T @ phi, phi.shape[0], names, groups, tol)


def excitation_from_gram(
    gram: np.ndarray,
    n: int,
    names: list[str],
    groups: dict[str, list[str]] | None = None,
    tol: float = 1e-6,
) -> ExcitationReport:
    """The same report from ΦᵀΦ (cheap for long logs): singular values of the unit-RMS-scaled
    regressor are the square roots of the eigenvalues of its scaled Gram matrix."""
    p = len(names)
    rms = np.sqrt(np.clip(np.diag(gram), 0.0, None) / max(n, 1))
    scale = rms.max() if rms.size and rms.max() > 0 else 1.0
    live = rms > tol * scale
    unexcited = [names[j] for j in range(p) if not live[j]]
    d = np.where(live, 1.0 / np.where(live, rms, 1.0), 0.0)
    normed = gram * np.outer(d, d) / max(n, 1)
    eig, vec = np.linalg.eigh(normed) if p else (np.array([]), np.zeros((0, 0)))
    sv = np.sqrt(np.clip(eig[::-1], 0.0, None))
    vec = vec[:, ::-1]
    rank = int(np.sum(sv > np.sqrt(tol) * (sv[0] if sv.size else 1.0)))
    condition = float((sv[0] / sv[p - 1]) ** 2) if p and sv[p - 1] > 0 else float("inf")
    collinear: list[str] = []
    n_live = int(live.sum())
    for k in range(n_live):
        if sv[k] < np.sqrt(tol) * sv[0]:
            collinear += [names[j] for j in np.flatnonzero(live & (np.abs(vec[:, k]) > 0.3))]
    collinear = sorted(set(collinear), key=names.index)
    group_min = {}
    for g, members in (groups or {}).items():
        cols = [names.index(m) for m in members]
        sub = np.linalg.eigvalsh(normed[np.ix_(cols, cols)])
        group_min[g] = float(np.sqrt(max(sub.min(), 0.0))) if sub.size else 0.0
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
        n, p, rank, condition, [float(x) for x in sv], group_min, unexcited, collinear, warnings
    )
