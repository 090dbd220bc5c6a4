"""The linear regression Φ θ = y that the least-squares and recursive estimators solve.

Physics models build it (:meth:`nnid.models.parametric.ParametricFossen.regression`); the
trainers only see the matrix, the target, the parameter names and which rows belong to which
DOF equation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Regression:
    """Φ θ = y stacked sample-major over the chosen DOF equations."""

    phi: np.ndarray  # [N * len(dofs), P]
    y: np.ndarray  # [N * len(dofs)]
    names: list[str]
    dofs: tuple[str, ...]
    n_samples: int
    #: the typical regressor size against which a column of rounding is zero
    #: (:func:`~nnid.evaluation.persistence.excitation_from_gram`) where the regression's own
    #: columns cannot give it (all of them rounding); 0: none but its own. A Fossen regression
    #: gives its regressors at the log's typical motion
    #: (:meth:`~nnid.models.parametric.ParametricFossen.motion_reference`)
    reference: float = 0.0

    def dof_rows(self, dof: str) -> np.ndarray:
        """Row indices of one DOF's equation."""
        k = self.dofs.index(dof)
        return np.arange(self.n_samples) * len(self.dofs) + k

    def residuals(self, theta: np.ndarray) -> list[np.ndarray]:
        """y − Φθ per DOF equation (NaN parameters count as zero)."""
        th = np.nan_to_num(theta)
        return [self.y[self.dof_rows(d)] - self.phi[self.dof_rows(d)] @ th for d in self.dofs]
