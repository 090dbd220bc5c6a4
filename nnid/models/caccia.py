"""Caccia's two-step model of one DOF as an ordinary estimator on logs (Caccia et al. 2000).

The log holds the steady-state campaign (experiments of constant thrust, plateaus) and,
optionally, the d-optimal sinusoid run (experiment ``sinusoid_experiment``); :meth:`fit` runs
:class:`nnid.trainers.caccia.CacciaTwoStep` on them: drag, installation coefficients and the
mean disturbance (weight minus buoyancy for heave) from the plateaus (eqs 7-12, 20), then the
inertia from the integrated equation of the sinusoid run (eqs 16-19). The identified one-DOF
model is a Fossen plant like any other (the vehicle file with the estimates in), so it predicts,
has a residual and saves like the other physics models; weight minus buoyancy is kept through a
save and load.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from typing import Literal

import pandas as pd

from nnid.datasets.log import run_of
from nnid.errors import NnidInputError
from nnid.models.parametric import (
    FROM_FILE,
    FossenPlant,
    ParametricFossen,
    canonical_parameter,
    restored_simulated,
    saved_from_file,
    simulated_values,
    warn_simulated,
    with_simulated_at,
)
from nnid.physics.dofs import DOFS
from nnid.physics.parts import WEIGHT_MINUS_BUOYANCY
from nnid.trainers.history import Progress
from nnid.trainers.least_squares import Estimate

#: Caccia's disturbance terms that are not parameters of a vehicle file
_NOT_FOSSEN = (WEIGHT_MINUS_BUOYANCY, "delta_weight")


def _fossen_names(names: Sequence[str]) -> list[str]:
    """The estimates that are vehicle-file parameters (the disturbance offsets are not)."""
    out = []
    for n in names:
        if n in _NOT_FOSSEN or n.startswith("delta_bias."):
            continue
        canonical_parameter(n)
        out.append(n)
    return out


class CacciaModel(FossenPlant):
    """Caccia's two-step identification of one uncoupled DOF (Caccia eqs 3, 7-20).

    ``CacciaModel(vehicle, dof="w").fit(log)``: every experiment except
    ``sinusoid_experiment`` is steady-state campaign; the sinusoid run, when present, gives the
    inertia (``Z_wdot`` for heave). The other arguments are those of
    :class:`nnid.trainers.caccia.CacciaTwoStep` (plateau rule, reference installation group,
    drag terms, row weighting, the step-2 velocity filter). ``params`` are in vehicle-file names
    and Fossen signs (``"Z:w"``, ``"Z:w*abs(w)"``, ``"eta.w.neg"``, ``"Z_wdot"``) plus
    ``weight_minus_buoyancy`` (heave) or ``external_bias.<dof>``; predictions fly the vehicle
    file with these estimates in, derived velocities using the step-2 filter.
    """

    kind = "caccia"
    window_key = "velocity_window"

    def __init__(
        self,
        vehicle,
        dof: str = "w",
        sinusoid_experiment: str = "sinusoid",
        reference: Sequence[Sequence[str]] = (("", "pos"),),
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
        self.vehicle = vehicle
        self.dof = dof
        self.sinusoid_experiment = sinusoid_experiment
        self.reference = reference
        self.mode_column = mode_column
        self.force_eta_one = force_eta_one
        self.terms = terms
        self.settings = settings
        self.settle_window = settle_window
        self.settle_order = settle_order
        self.settle_accel = settle_accel
        self.min_plateau = min_plateau
        self.speed = speed
        self.velocity_window = velocity_window
        self.velocity_order = velocity_order
        self.correlated = correlated
        self.weighting = weighting

    # the plant's velocities and accelerations are derived with the step-2 filter, its
    # velocity_window (window_key) named where that window is refused
    @property
    def savgol_window(self) -> float:
        return self.velocity_window

    @property
    def savgol_order(self) -> int:
        return self.velocity_order

    def _equation_dofs(self) -> Sequence[str]:
        """Its one DOF, before a fit sets ``dofs_`` to it too."""
        return getattr(self, "dofs_", None) or (self.dof,)

    def trainer(self):
        """The :class:`~nnid.trainers.caccia.CacciaTwoStep` procedure with these settings."""
        from nnid.trainers.caccia import CacciaTwoStep

        return CacciaTwoStep(
            dof=self.dof,
            reference=[tuple(r) for r in self.reference],
            mode_column=self.mode_column,
            force_eta_one=self.force_eta_one,
            terms=self.terms,
            settings=self.settings,
            settle_window=self.settle_window,
            settle_order=self.settle_order,
            settle_accel=self.settle_accel,
            min_plateau=self.min_plateau,
            speed=self.speed,
            velocity_window=self.velocity_window,
            velocity_order=self.velocity_order,
            correlated=self.correlated,
            weighting=self.weighting,
        )

    def _fit(self, log: pd.DataFrame, validation, progress: Progress) -> None:
        if self.dof not in DOFS:
            raise NnidInputError(f"'{self.dof}' is not a DOF; expected u v w p q r", field="dof")
        exp = log["experiment"] if "experiment" in log else pd.Series("0", index=log.index)
        # the sinusoid run's pieces (a gap cut it, run_of) are that run, never steady-state
        # experiments: step 2 then says why it cannot use them
        is_sine = (
            (exp == self.sinusoid_experiment) | (exp.map(run_of(log)) == self.sinusoid_experiment)
        ).to_numpy()
        if is_sine.all():
            raise NnidInputError(
                f"the log holds only the sinusoid run '{self.sinusoid_experiment}': step 1 needs "
                "steady-state experiments",
                field="sinusoid_experiment",
            )
        trainer = self.trainer()
        sinusoid = log[is_sine] if is_sine.any() else None
        if sinusoid is None:  # step 2 cannot run: the inertia the predictions fly is the file's
            warnings.warn(
                f"no training run is the sinusoid experiment '{self.sinusoid_experiment}' "
                f"(sinusoid_experiment): Caccia's step 2 did not run, the inertia is not "
                f"identified, and predictions use the vehicle file's added mass "
                f"{trainer.force_name}_{self.dof}dot",
                stacklevel=2,
            )
        estimate = trainer.fit_logs(log[~is_sine], self.vehicle, sinusoid)
        progress(1, 1, f"Caccia two-step, {len(trainer.plateaus_)} plateaus")
        self.trainer_ = trainer
        self._set_estimate(estimate)
        warn_simulated(self.from_file_, stacklevel=3)

    def _set_estimate(self, estimate: Estimate, state: Mapping | None = None) -> None:
        """Set the fitted plant from ``estimate``: its vehicle-file parameters in the vehicle
        file and heave's W − B as the buoyancy B = W − (W − B) (Caccia eq. 20), one it left
        unidentified (NaN: a zero regressor) at the file's value (:func:`simulated_values`;
        with a saved ``state``, as that model was: :func:`restored_simulated`)."""
        self.estimate_ = estimate
        fossen = _fossen_names(estimate.names)
        # W − B goes through the same simulated values: a NaN one made the buoyancy NaN
        flown = fossen + (
            [WEIGHT_MINUS_BUOYANCY]
            if self.dof == "w" and WEIGHT_MINUS_BUOYANCY in estimate.names
            else []
        )
        theta = estimate.theta[[estimate.names.index(n) for n in flown]]
        self.structure_ = ParametricFossen(self.vehicle, fossen, [self.dof])
        self._set_outputs([self.dof])
        if state is None:
            values, self.from_file_ = simulated_values(self.vehicle, flown, theta)
        else:
            # an older save flew a NaN W − B as a NaN buoyancy, not at 0 as the rest
            values, self.from_file_ = restored_simulated(
                state,
                self.vehicle,
                flown,
                theta,
                nan_before={WEIGHT_MINUS_BUOYANCY: "neutrally buoyant"},
            )
        wb = values.pop(WEIGHT_MINUS_BUOYANCY, None)
        self.parts_ = self.structure_.parts(values)
        if wb is not None:
            self.parts_.buoyancy = self.parts_.weight - wb

    def _params(self) -> dict[str, dict[str, float | None]]:
        return with_simulated_at(self.estimate_.as_dict(), self.from_file_)

    def describe(self) -> dict:
        return {
            **super().describe(),
            "vehicle": self.vehicle.name,
            "dof": self.dof,
            **self._procedure(),
        }

    def _procedure(self) -> dict:
        """What the two steps found: plateaus, the steady-state noise, where the inertia came
        from (step 2 ran on a sinusoid run, or the vehicle file's); as saved for a loaded
        model."""
        if not hasattr(self, "trainer_"):
            return dict(getattr(self, "procedure_", {}))
        return {
            "plateaus": len(self.trainer_.plateaus_),
            "steady_state_sigma2": self.trainer_.steady_.sigma2,
            "inertia": "identified" if self.trainer_.inertia_ is not None else "vehicle file",
        }

    def _state(self) -> tuple[dict, dict]:
        saved = {FROM_FILE: saved_from_file(self.from_file_)}
        return {**self.estimate_.as_state(), "procedure": self._procedure(), **saved}, {}

    def _restore(self, state: dict, tensors: dict) -> None:
        state = dict(state)
        procedure = state.pop("procedure", {})
        if not isinstance(procedure, dict):
            raise ValueError(f"procedure must be a table, not {procedure!r}")
        self.procedure_ = procedure
        simulated = {k: state.pop(k) for k in [FROM_FILE] if k in state}
        self._set_estimate(Estimate.from_state(state), simulated)
