"""Fault scenarios in the simulator: a thruster-driven vehicle flown as real ROVs fly, under an
attitude-stabilising controller, with a fault from a given time.

The controller tracks piecewise-constant random set-points of surge, sway, heave and yaw speed
(a velocity P loop) and holds roll and pitch level (a PD loop). Its demanded wrench goes through
the pseudo-inverse of the allocation matrix (:func:`nnid.physics.thrusters.allocation_matrix`),
each thrust is clipped to what its thruster can give and turned back into a command through the
inverse of its curve; the log records those commands as ``cmd_<thruster>``, as a real ROV's log
records its ESC commands, never the thrust the vehicle felt. The plant is the vehicle file (with
the scenario's effects) and is integrated by the compiled RK4 of the physics package.

Faults (:class:`Fault`), active from ``t`` (until ``end``, where one is given: a snag freed, a
thruster that recovers):

- ``thruster``: thruster ``thruster`` keeps ``efficiency`` (0 to 1) of its thrust (a damaged
  propeller, 0 for a stopped thruster);
- ``external``: a constant body-frame force and moment ``force`` (N, N m; a tether snag, a
  collision);
- ``effect``: an effect of the vocabulary with its value (:func:`nnid.physics.effects.apply_effect`;
  ``buoyancy_offset`` for a change of ballast);
- ``payload``: ``mass`` kilograms added at ``position`` (body frame, m; None: at the centre of
  gravity) with ``value`` newtons of buoyancy (the payload's displaced water) acting there;
  the vehicle and payload become one rigid body (the parallel-axis theorem).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import pandas as pd
import torch

from nnid.datasets.log import wrap_angle
from nnid.datasets.measurement import Measurement
from nnid.errors import NnidInputError
from nnid.physics import compiled
from nnid.physics.effects import apply_effect
from nnid.physics.fossen import FossenModel
from nnid.physics.thrusters import Actuation, apply_installation
from nnid.vehicle import point_mass_inertia, vehicle_copy


@dataclass(frozen=True)
class Fault:
    """One fault from time ``t`` (s) until ``end`` (s; None: to the end of the run); see the
    module docstring for the kinds."""

    kind: Literal["thruster", "external", "effect", "payload"]
    t: float
    thruster: str | None = None
    efficiency: float = 1.0
    force: tuple[float, ...] = (0.0,) * 6
    effect: str | None = None
    value: float = 0.0
    mass: float = 0.0
    end: float | None = None
    position: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class Controller:
    """The pilot: random speed set-points held ``hold`` seconds (uniform), at most ``speed``
    (u, v, w in m/s, r in rad/s), tracked with gains ``k_speed`` (N s/m, N m s); roll and pitch
    held level with ``k_att`` (N m/rad) and ``k_rate`` (N m s/rad)."""

    speed: tuple[float, float, float, float] = (0.4, 0.25, 0.2, 0.3)
    hold: tuple[float, float] = (2.0, 6.0)
    k_speed: tuple[float, float, float, float] = (40.0, 40.0, 40.0, 3.0)
    k_att: tuple[float, float] = (8.0, 8.0)
    k_rate: tuple[float, float] = (2.0, 2.0)

    def schedule(self, duration: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """Set-point switching times and values ``[K, 4]``."""
        times, values, t = [], [], 0.0
        while t < duration:
            times.append(t)
            values.append(rng.uniform(-1, 1, 4) * np.asarray(self.speed))
            t += rng.uniform(*self.hold)
        return np.asarray(times), np.asarray(values)

    def wrench(self, state: np.ndarray, ref: np.ndarray) -> np.ndarray:
        """Demanded generalized force ``[6]`` at ``state`` (η then ν) for set-point ``ref``."""
        nu = state[6:12]
        tau = np.zeros(6)
        k = np.asarray(self.k_speed)
        tau[[0, 1, 2, 5]] = k * (ref - nu[[0, 1, 2, 5]])
        att = wrap_angle(state[3:5])
        tau[3:5] = -np.asarray(self.k_att) * att - np.asarray(self.k_rate) * nu[3:5]
        return tau


class _Allocator:
    """Wrench -> commands: pseudo-inverse allocation, thrust saturation, inverse curves."""

    def __init__(self, actuation: Actuation) -> None:
        self.pinv = np.linalg.pinv(actuation.matrix)
        self.grids = []
        for thruster in actuation.thrusters:
            lo = -1.0 if thruster.cmd_min is None else thruster.cmd_min
            hi = 1.0 if thruster.cmd_max is None else thruster.cmd_max
            cmd = np.linspace(lo, hi, 2001)
            thrust = actuation.curves[len(self.grids)](cmd)
            if np.any(np.diff(thrust) < 0):
                raise NnidInputError(
                    f"thruster '{thruster.name}': the fault simulator needs a thrust curve that "
                    "grows with the command",
                    field="thrusters",
                )
            self.grids.append((thrust, cmd))

    def commands(self, wrench: np.ndarray) -> np.ndarray:
        force = self.pinv @ wrench
        out = np.empty(force.size)
        for i, (thrust, cmd) in enumerate(self.grids):
            out[i] = np.interp(np.clip(force[i], thrust[0], thrust[-1]), thrust, cmd)
        return out


def _with_payload(vehicle, mass: float, buoyancy: float, position: Sequence[float] | None = None):
    """The vehicle carrying ``mass`` kg at ``position`` (body frame, m; None: at its centre of
    gravity) with ``buoyancy`` N of lift acting there: the two bodies as one about the body
    origin (Fossen 2011 eq. 3.37, the parallel-axis theorem). The mass and weight add; the
    centre of gravity moves to m r_g + m_p r_p over their sum, the centre of buoyancy likewise
    by the buoyancies; I_o gains the payload's own inertia plus m_p(|r_p|² 1 − r_p r_pᵀ). Its
    own inertia is taken as the vehicle's about its centre of gravity by the share of mass,
    a fifth of it (a compact payload)."""
    r_g, r_b = np.asarray(vehicle.r_g, dtype=float), np.asarray(vehicle.r_b, dtype=float)
    r_p = r_g if position is None else np.asarray(position, dtype=float)
    inertia = np.asarray(vehicle.inertia_matrix(), dtype=float)
    about_cg = inertia - point_mass_inertia(vehicle.mass, r_g)
    own = 0.2 * mass / vehicle.mass * about_cg
    data = vehicle.model_dump()
    data["mass"] = vehicle.mass + mass
    data["weight"] = vehicle.weight + mass * vehicle.g
    data["buoyancy"] = vehicle.buoyancy + buoyancy
    data["r_g"] = ((vehicle.mass * r_g + mass * r_p) / data["mass"]).tolist()
    if data["buoyancy"] > 0:
        data["r_b"] = ((vehicle.buoyancy * r_b + buoyancy * r_p) / data["buoyancy"]).tolist()
    data["inertia"] = (inertia + own + point_mass_inertia(mass, r_p)).tolist()
    return vehicle_copy(vehicle, data)


def _plant_model(plant, active: Sequence[Fault]) -> FossenModel:
    """The Fossen model of the plant with the faults ``active``, refused as
    :func:`~nnid.datasets.simulator.check_mass_matrix` refuses a vehicle whose M is not
    positive definite, naming the faults that made it so (a raw ValueError before)."""
    from nnid.datasets.simulator import check_mass_matrix

    try:
        return check_mass_matrix(plant)
    except NnidInputError as exc:
        if not active:
            raise
        named = "; ".join(
            f"payload of {f.mass:g} kg" if f.kind == "payload" else f"{f.effect} = {f.value:g}"
            for f in active
        )
        onset = max(f.t for f in active)
        raise NnidInputError(
            f"with the fault {named} (from t = {onset:g} s): {exc.message}", field="faults"
        ) from None


def simulate_faults(
    vehicle,
    duration: float,
    dt: float = 0.05,
    *,
    faults: Sequence[Fault] = (),
    controller: Controller | None = None,
    measurement: Measurement | None = None,
    seed: int = 0,
    experiment: str | None = None,
) -> pd.DataFrame:
    """One experiment of ``duration`` seconds flown under ``controller`` with ``faults``; the
    log (log contract) has ``cmd_<thruster>`` inputs and the ``measurement``'s columns (default:
    DVL, gyro, attitude and depth with noise)."""
    if not vehicle.thrusters:
        raise NnidInputError("fault scenarios need a vehicle with [[thrusters]]", field="thrusters")
    controller = controller or Controller()
    measurement = measurement or Measurement(kind="dvl_imu")
    rng = np.random.default_rng(seed)
    names = [t.name for t in vehicle.thrusters]
    n = round(duration / dt) + 1
    switch, refs = controller.schedule(duration, rng)
    efficiency = np.ones((n, len(names)))
    external = np.zeros((n, 6))
    # the effect and payload faults active at each sample, as a key: one plant per distinct
    # set, so that one fault's end (or a later one's onset) is that plant's alone
    active: list[list[int]] = [[] for _ in range(n)]
    t = np.arange(n) * dt
    for index, fault in enumerate(faults):
        on = (t >= fault.t) & (t < (np.inf if fault.end is None else fault.end))
        if fault.kind == "thruster":
            if fault.thruster not in names:
                raise NnidInputError(
                    f"no thruster '{fault.thruster}'; the vehicle has {', '.join(names)}",
                    field="faults.thruster",
                )
            efficiency[on, names.index(fault.thruster)] = fault.efficiency
        elif fault.kind == "external":
            external[on] += np.asarray(fault.force, dtype=np.float64)
        else:  # payload or effect: a plant of its own
            for k in np.flatnonzero(on):
                active[k].append(index)
    keys = {(): 0}
    phase = np.array([keys.setdefault(tuple(a), len(keys)) for a in active], dtype=int)
    plants = []
    for key in keys:  # in order of their first use; () the healthy vehicle
        plant = vehicle
        for index in key:
            fault = faults[index]
            if fault.kind == "payload":
                plant = _with_payload(plant, fault.mass, fault.value, fault.position)
            else:
                plant = apply_effect(plant, fault.effect, fault.value)
        plants.append(plant)
    models = [
        _plant_model(v, [faults[i] for i in key]) for v, key in zip(plants, keys, strict=True)
    ]
    forms = [m.feature_form() for m in models]
    actuation = [Actuation(v) for v in plants]
    allocator = _Allocator(actuation[0])
    state = np.zeros(models[0].state_size)
    states = np.empty((n, state.size))
    commands = np.empty((n, len(names)))
    applied = np.empty((n, 6))
    for k in range(n):
        states[k] = state
        ref = refs[np.searchsorted(switch, t[k], side="right") - 1]
        commands[k] = allocator.commands(controller.wrench(state, ref))
        act = actuation[phase[k]]
        thrust = act.thrusts(commands[k : k + 1]) * efficiency[k]
        tau = apply_installation(thrust @ act.matrix.T, act.eta_pos, act.eta_neg)[0]
        applied[k] = tau + external[k]
        if k + 1 < n:
            state = compiled.integrate_rk4(forms[phase[k]], state, applied[k : k + 1], dt)[-1]
            if not np.isfinite(state).all():
                raise NnidInputError(
                    f"the fault simulation diverged at t = {t[k]:.2f} s", field="faults"
                )
    xdot = np.empty((n, 6))
    with torch.no_grad():
        for p, model in enumerate(models):
            rows = phase == p
            if rows.any():
                xdot[rows] = model.rhs(
                    torch.as_tensor(states[rows]), torch.as_tensor(applied[rows])
                ).numpy()[:, 6:12]
    columns: dict[str, np.ndarray] = {"t": t}
    if experiment is not None:
        columns["experiment"] = np.full(n, experiment, dtype=object)
    columns.update(measurement.columns(states, xdot, rng))
    columns.update({f"cmd_{c}": commands[:, i] for i, c in enumerate(names)})
    return pd.DataFrame(columns)
