"""Installation coefficients (Caccia eq. 3) act on the force commanded, before the vehicle's
first-order actuator lag 1/(T s + 1), in the regressions as in the simulator: the force felt is
L[η(sign τ) τ] = η⁺ L[τ⁺] + η⁻ L[τ⁻], not η(sign L[τ]) L[τ], which differ wherever the
commanded force changes sign within a lag time."""

from __future__ import annotations

import numpy as np
import pandas as pd
from conftest import make_vehicle

from nnid.datasets.arrays import force_arrays
from nnid.datasets.log import TAU
from nnid.datasets.preprocess import first_order_lag
from nnid.physics.parts import Parts
from nnid.physics.thrusters import apply_installation
from nnid.trainers.caccia import integrated_regression

LAG = 0.3
ETA = {"u.pos": 1.0, "u.neg": 0.6, "w.pos": 0.8, "w.neg": 1.3, "r.pos": 0.7, "r.neg": 0.7}


def _forces_log(rng, n: int = 400, dt: float = 0.05) -> pd.DataFrame:
    """Generalized forces through zero, changing sign within a lag time, two experiments."""
    tau = np.repeat(rng.normal(0, 20, (n // 4, 6)), 4, 0)  # held 0.2 s < T
    log = pd.DataFrame(tau, columns=list(TAU))
    log.insert(0, "t", np.tile(np.arange(n // 2) * dt, 2))
    log.insert(1, "experiment", np.repeat(["a", "b"], n // 2))
    return log


def test_the_force_felt_is_the_installed_force_through_the_lag(rng):
    vehicle = make_vehicle(actuator_lag=LAG, installation=ETA)
    log = _forces_log(rng)
    parts = Parts.from_vehicle(vehicle)
    tau = log[list(TAU)].to_numpy()
    felt = parts.felt(force_arrays(log, vehicle))
    np.testing.assert_allclose(felt, first_order_lag(parts.applied(tau), log, LAG), atol=1e-12)
    # the other order (installation of the lagged force) is what the regressions had: far off
    swapped = parts.applied(first_order_lag(tau, log, LAG))
    assert np.abs(swapped - felt)[:, [0, 2]].max() > 1.0


def test_equal_coefficients_and_no_lag_give_the_force_as_before(rng):
    """A DOF of equal coefficients, and a vehicle without a lag, see η(sign L[τ]) L[τ] to the
    last bit: their numbers do not move."""
    log = _forces_log(rng)
    lagged = make_vehicle(actuator_lag=LAG, installation=ETA)
    parts = Parts.from_vehicle(lagged)
    forces = force_arrays(log, lagged)
    symmetric = [1, 3, 4, 5]  # v p q (η = 1) and r (η⁺ = η⁻ = 0.7)
    assert np.array_equal(
        parts.felt(forces)[:, symmetric], parts.applied(forces["tau"])[:, symmetric]
    )
    unlagged = make_vehicle(installation=ETA)
    forces = force_arrays(log, unlagged)
    assert set(forces) == {"tau"}
    assert np.array_equal(parts.felt(forces), parts.applied(log[list(TAU)].to_numpy()))


def test_caccia_integrated_force_installs_before_the_lag(rng):
    """Caccia eq. 16's ϕ = ∫ η φⁿ of a lagged run is the integral of L[η φⁿ]."""
    log = _forces_log(rng, n=200).iloc[:100]
    forces = force_arrays(log, make_vehicle(actuator_lag=LAG))
    position = np.cumsum(rng.normal(0, 0.01, 100))
    args = (log["t"].to_numpy(), position)
    _, y, _ = integrated_regression(
        *args, forces["tau"][:, 2], 0.0, 0.0, 0.8, 1.3, 1.0, 2, forces["tau_neg"][:, 2]
    )
    tau_w = log["tau_Z"].to_numpy()
    installed = first_order_lag(apply_installation(tau_w, 0.8, 1.3), log, LAG)
    _, expected, _ = integrated_regression(*args, installed, 0.0, 0.0, 1.0, 1.0, 1.0, 2)
    np.testing.assert_allclose(y, expected, atol=1e-9)
