"""A log as the arrays the physics works on: pose η, velocity ν, acceleration ν̇, the nominal
generalized force τ (from ``tau_*`` or through the vehicle's thrusters from ``cmd_*``), time
and experiment codes."""

from __future__ import annotations

import numpy as np
import pandas as pd

from nnid.datasets.log import ANGLES, POSE, TAU, VELOCITY
from nnid.errors import NnidInputError
from nnid.physics.thrusters import Actuation


def motion_arrays(log: pd.DataFrame) -> dict[str, np.ndarray]:
    """η, ν, ν̇, time and experiment codes from a log (missing pose components are zero;
    velocities and accelerations must be present: derive them with
    :mod:`nnid.datasets.preprocess`)."""
    n = len(log)
    eta = np.zeros((n, 6))
    for k, c in enumerate(POSE):
        if c in log:
            eta[:, k] = log[c].to_numpy(np.float64)
    nu = np.zeros((n, 6))
    nu_dot = np.zeros((n, 6))
    for k, c in enumerate(VELOCITY):
        if c in log:
            nu[:, k] = log[c].to_numpy(np.float64)
        if "d" + c in log:
            nu_dot[:, k] = log["d" + c].to_numpy(np.float64)
    if "experiment" in log:
        codes, names = pd.factorize(log["experiment"])
    else:
        codes, names = np.zeros(n, dtype=int), ["0"]
    return {
        "eta": eta,
        "nu": nu,
        "nu_dot": nu_dot,
        "angles_known": np.array(all(a in log for a in ANGLES)),
        "t": log["t"].to_numpy(np.float64),
        "experiment": codes,
        "experiment_names": np.asarray(names, dtype=object),
    }


def log_arrays(log: pd.DataFrame, vehicle) -> dict[str, np.ndarray]:
    """:func:`motion_arrays` and the nominal τ (from ``tau_*`` or through the vehicle's
    thrusters from ``cmd_*``)."""
    if all(c in log for c in TAU):
        tau = log[list(TAU)].to_numpy(np.float64)
    else:
        act = Actuation(vehicle)
        cols = [f"cmd_{c}" for c in act.channels]
        missing = [c for c in cols if c not in log]
        if missing:  # a log's columns, not a setting: no config field to name
            present = [c for c in TAU if c in log]
            raise NnidInputError(
                "the log has neither the six generalized forces tau_X … tau_N"
                + (f" (only {', '.join(present)})" if present else "")
                + f" nor the commands {', '.join(missing)} of vehicle '{vehicle.name}'"
            )
        tau = act.nominal(log[cols].to_numpy(np.float64))
    return {**motion_arrays(log), "tau": tau}
