"""The linear regression Φ θ = y that the least-squares and recursive estimators solve.

Physics models build it (:meth:`nnid.models.parametric.ParametricFossen.regression`); the
trainers only see the matrix, the target, the parameter names and which rows belong to which
DOF equation.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np


@dataclass
class Regression:
    """Φ θ = y stacked sample-major over the chosen DOF equations."""

    phi: np.ndarray  # [N * len(dofs), P]
    y: np.ndarray  # [N * len(dofs)]
    names: list[str]
    dofs: tuple[str, ...]
    n_samples: int
    #: what gives each column's floor of the rounding rule
    #: (:func:`~nnid.evaluation.persistence.rounding_floors`), called by :meth:`floors` only
    #: where a solve reads them: a Fossen regression's are its columns at the log's typical
    #: motion (:meth:`~nnid.models.parametric.ParametricFossen.rounding_floors`), a cost that
    #: callers who read Φ alone (the loop's diagnosis, a sequence's step check) need not pay.
    #: None: no floors of its own; the rule compares the columns with each other
    motion: Callable[[], np.ndarray] | None = field(default=None, repr=False, compare=False)
    _floors: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)

    def floors(self) -> np.ndarray | None:
        """Each column's floor of the rounding rule ``[P]`` (NaN: none of its own), computed
        once, or None where the regression gives none (:attr:`motion`)."""
        if self.motion is None:
            return None
        if self._floors is None:
            self._floors = np.asarray(self.motion(), dtype=np.float64)
        return self._floors

    def dof_rows(self, dof: str) -> np.ndarray:
        """Row indices of one DOF's equation."""
        k = self.dofs.index(dof)
        return np.arange(self.n_samples) * len(self.dofs) + k

    def residuals(self, theta: np.ndarray) -> list[np.ndarray]:
        """y − Φθ per DOF equation (NaN parameters count as zero)."""
        th = np.nan_to_num(theta)
        return [self.y[self.dof_rows(d)] - self.phi[self.dof_rows(d)] @ th for d in self.dofs]
