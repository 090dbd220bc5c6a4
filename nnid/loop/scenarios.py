"""Simulated logs for the residual loop: every DOF excited, effects injected that the vehicle
file does not declare.

Each experiment drives all six generalized forces with independent random-phase multisines
(0.02-0.4 Hz), scaled from the vehicle's own damping and restoring so that the vehicle reaches
about ``speed`` m/s in translation, ``2 speed`` rad/s in yaw and about 0.2 rad in roll and
pitch (large roll excursions of a vehicle with little righting moment are chaotic: a free run
from a noisy initial state would then part from the log whatever the model). Measurement is
DVL/IMU-like by default, so the loop must derive accelerations.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import pandas as pd

from nnid.datasets.measurement import Measurement
from nnid.datasets.simulator import simulate
from nnid.physics.damping import parse_coefficient_key
from nnid.physics.dofs import DOFS, FORCES
from nnid.physics.parts import Parts


def force_amplitudes(vehicle, speed: float) -> np.ndarray:
    """Force per DOF that holds the vehicle near ``speed`` (``speed`` rad/s in roll and pitch,
    2 ``speed`` rad/s in yaw; roll and pitch also get 0.2 rad worth of restoring moment)."""
    parts = Parts.from_vehicle(vehicle)
    amp = np.zeros(6)
    for k, dof in enumerate(DOFS):
        v = 2 * speed if dof == "r" else speed  # roll and pitch gently: a capsize is chaotic
        lin = parts.damping.get(f"{FORCES[k]}:{dof}", 0.0)
        quad = next(
            (
                c
                for key, c in parts.damping.items()
                if parse_coefficient_key(key) == (FORCES[k], f"{dof}*abs({dof})")
            ),
            0.0,
        )
        amp[k] = abs(lin) * v + abs(quad) * v * v
    bg = abs(parts.weight * parts.r_g[2] - parts.buoyancy * parts.r_b[2])
    amp[3:5] += bg * np.sin(0.2)
    fallback = np.concatenate([np.full(3, parts.mass * speed), parts.inertia.diagonal() * speed])
    return np.where(amp > 0, amp, fallback)


def multisine_forces(
    n: int, dt: float, amplitudes: np.ndarray, rng: np.random.Generator, band=(0.02, 0.4)
) -> np.ndarray:
    """``[n, 6]`` sums of 8 random-phase sines per DOF at random frequencies in ``band``,
    scaled to the given peak amplitudes."""
    t = np.arange(n) * dt
    out = np.zeros((n, 6))
    for k in range(6):
        freqs = rng.uniform(*band, 8)
        phases = rng.uniform(0, 2 * np.pi, 8)
        x = np.sin(2 * np.pi * np.outer(t, freqs) + phases).sum(1)
        out[:, k] = amplitudes[k] * x / np.abs(x).max()
    return out


def effect_log(
    vehicle,
    effects: Sequence[tuple[str, float]] = (),
    *,
    duration: float = 600.0,
    dt: float = 0.05,
    n_experiments: int = 6,
    speed: float | Sequence[float] = 0.4,
    seed: int = 0,
    measurement: Measurement | None = None,
    unlogged: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
) -> pd.DataFrame:
    """A log of ``n_experiments`` runs sharing ``duration`` seconds, all DOFs excited, with
    ``effects`` injected into the plant (:func:`nnid.physics.effects.apply_effect`). A list
    of ``speed`` cycles over the experiments (slow and fast runs in one campaign).
    ``unlogged(t, forces)`` ``[n, 6]``: a force that acts on the plant but is not in the log
    (an effect outside the vocabulary: a tether's tug, a thruster's distortion)."""
    if vehicle.thrusters:
        raise ValueError("effect_log drives generalized forces; use a vehicle without thrusters")
    rng = np.random.default_rng(seed)
    measurement = measurement or Measurement(kind="dvl_imu")
    speeds = [speed] if np.isscalar(speed) else list(speed)
    n = round(duration / n_experiments / dt)
    logs = []
    for i in range(n_experiments):
        amp = force_amplitudes(vehicle, float(speeds[i % len(speeds)]))
        forces = multisine_forces(n, dt, amp, rng)
        acting = forces if unlogged is None else forces + unlogged(np.arange(n) * dt, forces)
        log = simulate(
            vehicle,
            acting,
            dt,
            effects=effects,
            measurement=measurement,
            seed=seed * 1000 + i,
            experiment=f"run{i}",
        )
        if unlogged is not None:
            log[[f"tau_{f}" for f in FORCES]] = forces
        logs.append(log)
    return pd.concat(logs, ignore_index=True)
