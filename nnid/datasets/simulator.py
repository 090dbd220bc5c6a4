"""The simulator that makes synthetic logs from a vehicle, inputs and injected effects.

The plant is the vehicle with the injected effects applied (:mod:`nnid.physics.effects`); the
log records the *nominal* inputs, so an effect the vehicle file does not declare is in the data
and not in the model. Inputs are held constant over each sample (zero-order hold).

Integrators: ``rk4`` (fixed step with sub-steps, compiled), ``adaptive`` (SciPy's DOP853 with
error control on the same right-hand side) and ``torch`` (batched, differentiable, for checks
and gradients).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterable, Sequence
from typing import Annotated

import numpy as np
import pandas as pd
import torch
from pydantic import Field, field_validator
from scipy.integrate import solve_ivp

from nnid.datasets.arrays import far_beyond_range, warn_clipped, warn_far_beyond_range
from nnid.datasets.excitation import DOptimalSine, Step, same_draws, ticks
from nnid.datasets.log import TAU, wrap_angle
from nnid.datasets.measurement import Measurement
from nnid.errors import ExcitationWarning, NnidInputError
from nnid.physics import compiled
from nnid.physics.dofs import FORCES
from nnid.physics.effects import apply_effect
from nnid.physics.fossen import FossenModel
from nnid.physics.integrate import rk4
from nnid.physics.thrusters import Actuation
from nnid.validation import StrictModel

INTEGRATORS = ("rk4", "adaptive", "torch")


Gain = Annotated[float, Field(ge=0, allow_inf_nan=False)]


class Autopilot(StrictModel):
    """A digital PD autopilot on generalized forces, evaluated once per sample and held:
    τ_fb = −k_p (η − η_ref) − k_d ν per DOF (heading error wrapped to ±π), the x/y terms (north
    and east errors) turned into surge and sway by the heading ψ (R_z(ψ)ᵀ; Fossen's kinematics
    eq. with roll and pitch taken small, so that an autopilot without x/y gains keeps its law
    and its logs bit for bit). DOFs with k_p = k_d = 0 are left free. Open-loop-unstable
    vehicles (an AUV without its fin controller, McCarter ch. 5) fly under it; the log records
    the total commanded force, feedback included.
    """

    # a negative gain is positive feedback: the autopilot would drive the vehicle away
    kp: list[Gain] = Field(default_factory=lambda: [0.0] * 6, min_length=6, max_length=6)
    kd: list[Gain] = Field(default_factory=lambda: [0.0] * 6, min_length=6, max_length=6)
    reference: list[Annotated[float, Field(allow_inf_nan=False)]] = Field(
        default_factory=lambda: [0.0] * 6, min_length=6, max_length=6
    )

    @field_validator("reference")
    @classmethod
    def _radians(cls, reference: list[float]) -> list[float]:
        if any(abs(a) > 2 * math.pi for a in reference[3:]):  # 90 was wrapped to 2.04 rad
            raise ValueError("its angles (the last three) are in radians: one is beyond 2π")
        return reference

    def force(self, state: np.ndarray) -> np.ndarray:
        """The feedback force ``[..., 6]`` for states ``[..., 12]`` (η then ν)."""
        error = state[..., 0:6] - np.asarray(self.reference)
        error[..., 3:6] = wrap_angle(error[..., 3:6])
        push = -np.asarray(self.kp) * error
        if self.kp[0] or self.kp[1]:
            # the x/y gains push north and east (NED errors); surge and sway are body forces,
            # so the push turns by the heading: unturned, it flipped sign at ψ = π
            cos, sin = np.cos(state[..., 5]), np.sin(state[..., 5])
            north, east = push[..., 0].copy(), push[..., 1].copy()
            push[..., 0] = cos * north + sin * east
            push[..., 1] = -sin * north + cos * east
        return push - np.asarray(self.kd) * state[..., 6:12]

    def pilot(self, eta_pos: np.ndarray, eta_neg: np.ndarray) -> np.ndarray:
        """The autopilot and the installation coefficients it flies through, as
        :func:`nnid.physics.compiled.fly_pd` takes them: ``[5, 6]`` k_p, k_d, η_ref, η⁺, η⁻."""
        return np.vstack([self.kp, self.kd, self.reference, eta_pos, eta_neg]).astype(float)


def plant(vehicle, effects: Iterable[tuple[str, float]] = ()):
    """The vehicle with the injected effects applied, in order."""
    for name, value in effects:
        vehicle = apply_effect(vehicle, name, value)
    return vehicle


def check_mass_matrix(vehicle) -> FossenModel:
    """Refuse to fly a vehicle whose M = M_RB + M_A is not positive definite (its equations of
    motion have no solution): an :class:`NnidInputError` naming ``added_mass`` where the
    rigid body alone is positive definite, else no field (mass, inertia and r_g together). Not
    a check of loading: a fit refits the added mass of such a file. Returns the model the
    check built (Weiss eq. 1), for a caller that flies the vehicle as it is."""
    try:
        return FossenModel.from_vehicle(vehicle)
    except ValueError as exc:
        try:
            FossenModel.from_vehicle(vehicle.model_copy(update={"added_mass": {}}))
            field = "added_mass"
        except ValueError:
            field = None
        raise NnidInputError(str(exc), field=field) from None


#: |cos θ| below which a simulated pitch is refused (within 0.006° of ±90°): the Euler-angle
#: kinematics divide by it, and a run through θ = 90° came back with φ = ψ = −3.4e12 rad after
#: one step. Weiss's own Seamor sequence pitches to 89.5° (cos θ = 0.009) in its surge-heave
#: run, which the RK4 steps still follow
GIMBAL_COS = 1e-4


def integrate(
    model: FossenModel,
    x0: np.ndarray,
    tau: np.ndarray,
    dt: float,
    substeps: int = 1,
    integrator: str = "rk4",
    rtol: float = 1e-8,
    atol: float = 1e-10,
) -> np.ndarray:
    """States at the ``len(tau) + 1`` sample times for applied forces ``tau`` ``[N, 6]`` (ZOH).
    ``rk4`` (:mod:`nnid.physics.compiled`) and ``torch`` step an actuator lag by its exact
    exponential; ``adaptive`` integrates it as a state."""
    if integrator == "rk4":
        return compiled.integrate_rk4(model.feature_form(), x0, tau, dt, substeps)
    if integrator == "torch":
        x0, tau = torch.as_tensor(x0), torch.as_tensor(tau)
        out = rk4(model.rhs, x0, tau, dt, substeps, lag=model.actuator_lag)
        return out.numpy()
    if integrator == "adaptive":
        form = model.feature_form()
        n = tau.shape[0]

        def fun(t, x):
            k = min(int(ticks(t, dt)), n - 1)  # the signals' clock rule: t/dt is inexact
            return compiled.rhs(form, x, tau[k])

        t_eval = np.arange(n + 1) * dt
        sol = solve_ivp(
            fun,
            (0.0, t_eval[-1]),
            x0,
            method="DOP853",
            t_eval=t_eval,
            rtol=rtol,
            atol=atol,
            max_step=dt,
        )
        # a failed solve (its step shrank below rounding: the state ran away) is a diverged
        # run: NaN from the first sample not reached, which :func:`simulate` says as the
        # fixed-step integrators' divergence (a bare RuntimeError was a traceback in the CLI)
        states = np.full((n + 1, x0.size), np.nan)
        if sol.y.size:
            states[: sol.y.shape[1]] = sol.y.T
        return states
    raise ValueError(f"unknown integrator '{integrator}'; expected one of {INTEGRATORS}")


def simulate(
    vehicle,
    inputs: np.ndarray,
    dt: float,
    *,
    effects: Sequence[tuple[str, float]] = (),
    x0: Sequence[float] | None = None,
    substeps: int = 1,
    integrator: str = "rk4",
    measurement: Measurement | None = None,
    seed: int = 0,
    experiment: str | None = None,
    autopilot: Autopilot | None = None,
) -> pd.DataFrame:
    """Simulate one experiment and return its log (log contract).

    ``inputs`` is ``[N, n_channels]``: thruster commands in the order of ``vehicle.thrusters``,
    or generalized forces ``X Y Z K M N`` for a vehicle without thrusters; sample k is applied
    over [k dt, (k+1) dt). The log has N rows at t = k dt. With an ``autopilot`` (vehicles
    without thrusters only) the feedback is added to the inputs sample by sample.
    Raises :class:`NnidInputError` if the trajectory diverges.
    """
    inputs = np.atleast_2d(np.asarray(inputs, dtype=np.float64))
    truth = plant(vehicle, effects)
    actuation = Actuation(truth)
    if inputs.shape[1] != len(actuation.channels):
        raise ValueError(
            f"inputs have {inputs.shape[1]} channels; the vehicle has {len(actuation.channels)} "
            f"({', '.join(actuation.channels)})"
        )
    # the vehicle's own M first: the effects are not at fault then; without effects the
    # model that check built is the plant (building it again gave the same model)
    model = check_mass_matrix(vehicle)
    if truth is not vehicle:
        try:
            model = FossenModel.from_vehicle(truth)
        except ValueError as exc:  # an injected effect no vehicle can have (a negative mass)
            raise NnidInputError(str(exc), field="effects") from None
    state = np.zeros(model.state_size)
    if x0 is not None:
        state[: len(x0)] = np.asarray(x0, dtype=np.float64)
    if vehicle.thrusters:  # clipped to the range silently: the log would record the asked
        # PWM microseconds against ±1 would fly every run at full thrust: said once, as the
        # unit slip it is, and not again as a saturation of the same thruster
        asked = pd.DataFrame(inputs, columns=[f"cmd_{c}" for c in actuation.channels])
        slips = far_beyond_range(asked, vehicle)
        warn_far_beyond_range(asked, vehicle, slips)
        warn_clipped(inputs, vehicle, experiment, said_units=[s.column for s in slips])
    if autopilot is None:
        applied = actuation.applied(inputs)
        states = integrate(model, state, applied[:-1], dt, substeps, integrator)
    else:
        if vehicle.thrusters:
            raise NnidInputError(
                "the autopilot commands generalized forces; this vehicle has thrusters",
                field="autopilot",
            )
        inputs, applied, states = _closed_loop(
            model, actuation, autopilot, state, inputs, dt, substeps, integrator
        )
    if not np.isfinite(states).all():
        k = int(np.flatnonzero(~np.isfinite(states).all(1))[0])
        raise NnidInputError(
            f"the simulation diverged at t = {k * dt:.2f} s"
            + (f" in experiment '{experiment}'" if experiment else "")
            + ": the vehicle is unstable for these inputs (check damping signs and amplitudes, "
            "or fly it under an autopilot)",
            field="experiments",
        )
    near = np.flatnonzero(np.abs(np.cos(states[:, 4])) < GIMBAL_COS)
    if near.size:  # J(η) divides by cos θ: the attitude is garbage there, not a measurement
        k = int(near[0])
        raise NnidInputError(
            f"the vehicle pitched to {np.degrees(states[k, 4]):.1f}° at t = {k * dt:.2f} s"
            + (f" in experiment '{experiment}'" if experiment else "")
            + ": Euler angles are singular at ±90° of pitch (Weiss eq. 17) and the simulator "
            "integrates them; lower the pitch moments, or fly it under an autopilot",
            field="experiments",
        )
    with torch.no_grad():
        xdot = model.rhs(torch.as_tensor(states), torch.as_tensor(applied)).numpy()
    measurement = measurement or Measurement()
    rng = np.random.default_rng(seed)
    t = np.arange(inputs.shape[0]) * dt
    columns: dict[str, np.ndarray] = {"t": t}
    if experiment is not None:
        columns["experiment"] = np.full(t.size, experiment, dtype=object)
    columns.update(measurement.columns(states, xdot[:, 6:12], rng))
    if vehicle.thrusters:
        columns.update({f"cmd_{c}": inputs[:, k] for k, c in enumerate(actuation.channels)})
    else:
        columns.update({c: inputs[:, k] for k, c in enumerate(TAU)})
    return pd.DataFrame(columns)


def _closed_loop(model, actuation, autopilot, state, inputs, dt, substeps, integrator):
    """Step the plant one sample at a time, adding the autopilot's held feedback force (the
    RK4 in one compiled loop, :func:`nnid.physics.compiled.fly_pd`)."""
    n = inputs.shape[0]
    commanded = inputs.copy()
    if integrator == "rk4":
        pilot = autopilot.pilot(actuation.eta_pos, actuation.eta_neg)
        flown, record = compiled.fly_pd(
            model.feature_form(),
            state,
            inputs,
            np.zeros(1, int),
            n - 1,
            dt,
            pilot,
            actuation.deadband,
            substeps,
            True,
        )
        states = flown[0]
        bad = np.flatnonzero(~np.isfinite(states).all(1))
        done = n - 1 if bad.size == 0 else int(bad[0])  # commands flown before the divergence
        commanded[:done] = record[0, :done]
    else:
        states = np.empty((n, state.size))
        states[0] = state
        for k in range(n - 1):
            commanded[k] = inputs[k] + autopilot.force(states[k])
            applied = actuation.applied(commanded[k : k + 1])
            states[k + 1] = integrate(model, states[k], applied, dt, substeps, integrator)[-1]
            if not np.isfinite(states[k + 1]).all():
                states[k + 2 :] = np.nan
                break
    commanded[-1] = inputs[-1] + autopilot.force(states[-1])
    return commanded, actuation.applied(commanded), states


def experiment_inputs(
    experiment, channels: Sequence[str], dt: float, where: str | None = ""
) -> np.ndarray:
    """Inputs ``[N, len(channels)]`` of a config experiment: its signals summed per channel;
    ``where`` prefixes the fields an error names (None: a run of the config's ``sequence``)."""
    end = experiment.end()
    if end <= 0:
        raise NnidInputError(
            "the experiment has no duration: give 'duration' or signals that end",
            field="sequence" if where is None else f"{where}duration",
        )
    t = np.arange(round(end / dt) + 1) * dt
    inputs = np.zeros((t.size, len(channels)))
    for j, signal in enumerate(experiment.signals):
        if signal.channel not in channels:
            if where is None:
                raise NnidInputError(
                    f"the sequence drives the forces {', '.join(FORCES)}: a vehicle without "
                    f"thrusters takes them; this one takes {', '.join(channels)}",
                    field="sequence",
                )
            raise NnidInputError(
                f"'{signal.channel}' is not an input of this vehicle; expected one of "
                f"{', '.join(channels)}",
                field=f"{where}signals.{j}.channel",
            )
        field = "sequence" if where is None else f"{where}signals.{j}"
        if isinstance(signal, DOptimalSine) and signal.channel not in FORCES:
            # its frequency is designed from its offset as a force (Caccia eqs 13-14); a
            # thruster's offset is a command, in the command's units (docs: signal keys)
            raise NnidInputError(
                f"a doptimal_sine designs its frequency from its offset as a force (Caccia "
                f"eqs 13-14); '{signal.channel}' is a thruster, whose offset is a command: "
                "expected a generalized force channel (X Y Z K M N) of a vehicle without "
                'thrusters; a thruster vehicle flies it by [data] kind = "caccia_campaign"',
                field=f"{field}.channel" if where is not None else field,
            )
        if (
            isinstance(signal, Step)
            and signal.duration is None
            and experiment.duration is None
            and signal.start >= end
            and where is not None
        ):  # held to the run's end, which the other signals set before its start
            raise NnidInputError(
                f"a step without 'duration' is held to the experiment's end, and the "
                f"experiment has no 'duration': its end is its signals' last end ({end:g} s), "
                f"at or before this step's start ({signal.start:g} s); expected a 'duration' "
                "for the experiment (or for the step)",
                field=f"{where}duration",
            )
        if signal.start >= end or signal.start > t[-1]:  # it would never act
            raise NnidInputError(
                f"starts at {signal.start:g} s, at or after the experiment's end ({end:g} s): "
                "it would never act",
                field=f"{field}.start" if where is not None else field,
            )
        key = next((k for k in ("hold", "hold_min") if getattr(signal, k, None)), None)
        if key is not None and getattr(signal, key) < dt:  # levels never seen between samples
            raise NnidInputError(
                f"holds a level {getattr(signal, key):g} s, shorter than the sample time "
                f"dt = {dt:g} s: some levels would never be sampled",
                field=f"{field}.{key}" if where is not None else field,
            )
        length = getattr(signal, "duration", None)
        if length is not None and length < dt:  # a pulse between two samples: never flown
            raise NnidInputError(
                f"lasts {length:g} s, shorter than the sample time dt = {dt:g} s: the inputs "
                "are held over each sample, so it would be flown a whole sample or not at all",
                field=f"{field}.duration" if where is not None else field,
            )
        if signal.end() > end + dt / 2:  # cut by the experiment's duration: said, not dropped
            warnings.warn(
                f"{field}: the signal ends at {signal.end():g} s, after the experiment's end "
                f"({end:g} s, its duration): its last {signal.end() - end:g} s are not flown",
                stacklevel=2,
            )
        inputs[:, channels.index(signal.channel)] += signal(t)
    return inputs


def simulate_config(config, vehicle, progress=None) -> pd.DataFrame:
    """Run every experiment of a :class:`nnid.config.SimulateConfig`; one log, ``experiment``
    separating the runs. ``progress(done, total, message)`` is called after each experiment."""
    experiments = config.all_experiments()
    channels = Actuation(vehicle).channels
    logs = []
    for i, exp in enumerate(experiments):
        # the sequence's runs follow the explicit ones: their fields are the sequence's
        where = f"experiments.{i}." if i < len(config.experiments) else None
        inputs = experiment_inputs(exp, channels, config.dt, where=where)
        for group in same_draws(exp.signals):
            first = exp.signals[group[0]]
            # each signal's own seed: a group may hold different ones (a PRBS's 1 and 128
            # start its register alike), and the first alone read as one seed shared
            seeds = [getattr(exp.signals[j], "seed", None) for j in group]
            seed = (
                f"seed {seeds[0]}"
                if len(set(seeds)) == 1
                else "seeds "
                + ", ".join(
                    f"{s} on {exp.signals[j].channel}" for j, s in zip(group, seeds, strict=True)
                )
            )
            warnings.warn(
                f"experiment {exp.name!r}: the {first.kind} signals on "
                f"{', '.join(exp.signals[j].channel for j in group)} draw the same sequence "
                f"({seed}, the same holds): their inputs are "
                "collinear (correlation ±1) and a fit cannot tell the channels apart; give each "
                "its own 'seed' (the config's seed and --seed move the sensor noise only)",
                ExcitationWarning,
                stacklevel=2,
            )
        effects = [(e.name, e.value) for e in (*config.effects, *exp.effects)]
        logs.append(
            simulate(
                vehicle,
                inputs,
                config.dt,
                effects=effects,
                x0=exp.x0,
                substeps=config.substeps,
                integrator=config.integrator,
                measurement=config.measurement,
                seed=config.seed + i,
                experiment=exp.name,
                autopilot=config.autopilot,
            )
        )
        if progress:
            progress(i + 1, len(experiments), f"simulated {exp.name}")
    return pd.concat(logs, ignore_index=True)


def open_loop_inputs(config, log: pd.DataFrame) -> pd.DataFrame:
    """The open-loop part (``tau_X … tau_N``) of the inputs a simulate config flew under its
    autopilot, on the log's index: each experiment's signals regenerated (the log records
    them plus the autopilot's feedback). Experiments of the log that the config does not
    define are an error."""
    out = pd.DataFrame(np.nan, index=log.index, columns=list(TAU))
    names = log["experiment"] if "experiment" in log else pd.Series("", index=log.index)
    runs = {e.name: e for e in config.all_experiments()}
    for name in pd.unique(names):
        if name not in runs:
            raise NnidInputError(
                f"experiment {name!r} is not one of the simulate config's", field="experiments"
            )
        rows = np.flatnonzero((names == name).to_numpy())  # by position: labels may repeat
        inputs = experiment_inputs(runs[name], FORCES, config.dt)
        if len(inputs) < len(rows):
            raise NnidInputError(
                f"experiment {name!r} has more rows than its simulation", field="experiments"
            )
        out.iloc[rows] = inputs[: len(rows)]
    return out
