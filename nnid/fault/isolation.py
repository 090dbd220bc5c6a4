"""Isolation and estimation: which thruster or which effect a change is, and how large.

On the window after an alarm, the force residual r of the monitor is explained in turn by each
hypothesis, with the residual loop's own scoring (:func:`nnid.loop.diagnose.screen`: the exact
one-column least-squares refit, its F-test with the residual's correlation time, the standard
error) and the loop's own candidates (:func:`nnid.loop.effects.candidates`, their regressor
columns from :class:`nnid.models.parametric.ParametricFossen`): one implementation of "name the
effect". The fault hypotheses added here are the thrusters: thruster i losing a fraction s of its
thrust leaves r = −s bᵢ fᵢ (bᵢ its allocation column, fᵢ its nominal thrust), so its column is
bᵢ fᵢ and its remaining efficiency is 1 − s.

Kinds: ``thruster_loss`` (a thruster), ``external_force`` (``external_bias.<dof>``: a constant
force such as a tether snag) and ``model_change`` (any other effect: ``buoyancy_offset`` for a
payload, ``added_mass.<dof>``, damping). A thruster's signature follows its command, an external
force is constant in the body frame, a buoyancy change follows the attitude; a constant external
force in several DOFs at once (a tether pulling at a point off the centre) is one more
hypothesis, the external_bias columns of all DOFs together, weighed against the one-parameter
hypotheses by its penalised likelihood (BIC). Hypotheses whose
whitened columns are nearly parallel on the window cannot be told apart by the data; among them
the physically likelier is named (a thruster, then a buoyancy change: a vertical constant force on
a level vehicle is a ballast change more often than a tether pulling down), and the confidence is
the posterior weight of the whole group, so it says how sure the *group* is.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np
import pandas as pd
from scipy.stats import f as f_dist

from nnid.datasets.log import POSE, TAU, VELOCITY
from nnid.loop.diagnose import Fit, screen
from nnid.loop.effects import Candidate, candidates
from nnid.models.parametric import ParametricFossen, vehicle_with
from nnid.physics.thrusters import Actuation

_PRIORITY = {"thruster_loss": 0, "buoyancy_offset": 1, "external_bias": 2}
PARALLEL = 0.95  # |cos| of whitened columns above which two hypotheses are one to the data
SIGNIFICANCE = 0.01


@dataclass
class Diagnosis:
    """What changed: ``kind``, the ``thruster`` and its ``efficiency`` (with a 95 % interval),
    or the ``effect`` with its ``value`` and ``stderr`` (and, for a constant external force in
    several DOFs, every component in ``wrench``); ``confidence`` the posterior weight (BIC) of
    the named hypothesis and those the data cannot tell from it; ``alternatives`` the next
    ones."""

    kind: str
    thruster: str | None = None
    efficiency: float | None = None
    efficiency_interval: tuple[float, float] | None = None
    effect: str | None = None
    value: float | None = None
    stderr: float | None = None
    confidence: float = 0.0
    explained: float = 0.0
    p_value: float | None = None
    meaning: str = ""
    alternatives: list[dict] = field(default_factory=list)
    wrench: dict[str, dict[str, float]] | None = None  # components of a constant external force


def fitted_vehicle(plant):
    """The monitor's model as a vehicle file: its vehicle with the fitted values written in
    (the vehicle itself where the model's parameter names are not the vehicle file's)."""
    values = {k: v["value"] for k, v in plant.params.items() if v.get("value") is not None}
    try:
        return vehicle_with(plant.vehicle, values)
    except Exception:
        return plant.vehicle


def midpoint_data(data: dict, rows: np.ndarray, vehicle) -> tuple[dict, pd.DataFrame]:
    """The arrays of the intervals ending at ``rows`` as the regression sees them: pose and
    velocity at the midpoint, acceleration the difference quotient, the force of the commands
    held over the interval (the monitor's residual is this equation's error)."""
    x, x0 = data["x"][rows], data["x"][rows - 1]
    mid = 0.5 * (x + x0)
    step = x[:, 3:6] - x0[:, 3:6]
    step -= 2 * np.pi * np.floor((step + np.pi) / (2 * np.pi))
    mid[:, 3:6] = x0[:, 3:6] + 0.5 * step
    dt = (data["t"][rows] - data["t"][rows - 1])[:, None]
    act = Actuation(vehicle)
    inputs = data["inputs"][rows - 1]
    tau = act.nominal(inputs) if act.thrusters else inputs
    arrays = {
        "eta": mid[:, 0:6],
        "nu": mid[:, 6:12],
        "nu_dot": (x[:, 6:12] - x0[:, 6:12]) / dt,
        "tau": tau,
        "angles_known": np.array(True),
        "t": data["t"][rows] - 0.5 * dt[:, 0],
        "experiment": np.zeros(rows.size, dtype=int),
        "experiment_names": np.array(["window"], dtype=object),
    }
    frame = pd.DataFrame(np.concatenate([mid, tau], 1), columns=[*POSE, *VELOCITY, *TAU])
    frame.insert(0, "t", arrays["t"])
    return arrays, frame


def isolate(monitor, data: dict, residual: np.ndarray, rows: np.ndarray) -> Diagnosis:
    """Name the change behind the monitor's residual ``residual`` [N, 6] on ``rows`` (indices
    into ``data`` of :func:`nnid.fault.monitor.monitor_inputs`, each with its predecessor)."""
    plant = monitor.plant_
    rows = rows[(rows > 0) & np.isfinite(residual[rows]).all(1)]
    if rows.size < 10:
        return Diagnosis("model_change", meaning="too few samples after the alarm to isolate")
    vehicle = fitted_vehicle(plant)
    arrays, frame = midpoint_data(data, rows, vehicle)
    e = residual[rows] - monitor.mu_
    # the thrusters themselves stand for thrust changes; a DOF's installation coefficient
    # would only be a coarser copy of them
    cands = [
        c
        for c in candidates(vehicle, frame, coupled=False)
        if c.linear and c.kind != "thruster_installation"
    ]
    reg = ParametricFossen(vehicle, [c.parameter for c in cands]).regression(arrays)
    cols = reg.phi.reshape(rows.size, 6, len(cands))
    act = Actuation(plant.vehicle)
    if act.thrusters:
        thrust = act.thrusts(data["inputs"][rows - 1])  # [N, n]
        own = thrust[:, None, :] * act.matrix[None, :, :]  # bᵢ fᵢ, [N, 6, n]
        cands += [
            Candidate(f"thruster_loss.{n}", "thruster_loss", f"thruster.{n}") for n in act.channels
        ]
        cols = np.concatenate([cols, own], 2)
    mask = monitor.mask_
    sigma2 = np.where(mask > 0, monitor.sigma_**2, 1.0)
    weights = mask / sigma2
    ws = SimpleNamespace(weights=weights, dofs=plant.dofs_, tau_corr=monitor.correlation_time_)
    empty = np.zeros((rows.size, 6, 0))
    rss = float(np.sum(e**2 * weights))
    fit = Fit(vehicle, [], np.zeros(0), np.zeros(0), empty, empty, e, e, rss)
    with np.errstate(invalid="ignore", divide="ignore"):
        scored = screen(ws, fit, cands, cols, cols)
    if not scored:
        return Diagnosis("model_change", meaning="no hypothesis has a signature on this window")
    scored.sort(key=lambda s: -s.drss)
    index = {c.name: k for k, c in enumerate(cands)}
    # penalised log-likelihood (BIC): one parameter each, and the constant external wrench,
    # whose columns (the external_bias.<dof> of every DOF watched) fit jointly what they fit
    # one by one: they have disjoint rows and the weights are per DOF
    penalty = 0.5 * np.log(max(rows.size * len(plant.dofs_) / ws.tau_corr, 2.0))
    logl = np.array([s.drss for s in scored]) / (2 * ws.tau_corr) - penalty
    parts = [s for s in scored if s.candidate.kind == "external_bias"]
    wrench_logl = sum(s.drss for s in parts) / (2 * ws.tau_corr) - len(parts) * penalty
    top = max(logl.max(), wrench_logl)
    post = np.exp(np.r_[logl, wrench_logl] - top)
    post /= post.sum()
    if len(parts) > 1 and wrench_logl > logl.max():
        return _wrench(parts, ws, rows.size, rss, scored, post)
    post = post[:-1]
    best = scored[0]
    white = cols * np.sqrt(weights)[None, :, None]
    b = white[:, :, index[best.name]].ravel()
    group = []
    for k, s in enumerate(scored):
        c = white[:, :, index[s.name]].ravel()
        cos = abs(b @ c) / max(np.linalg.norm(b) * np.linalg.norm(c), 1e-300)
        if k == 0 or (cos > PARALLEL and s.drss >= 0.9 * best.drss):
            group.append(k)
    named = min(group, key=lambda k: (_PRIORITY.get(scored[k].candidate.kind, 9), k))
    s = scored[named]
    out = Diagnosis(
        _kind(s),
        confidence=float(post[group].sum()),
        explained=float(s.drss / rss) if rss > 0 else 0.0,
        p_value=float(s.p_value),
        meaning=s.candidate.meaning,
        alternatives=[
            {"hypothesis": scored[k].name, "posterior": float(post[k])}
            for k in range(len(scored))
            if k != named
        ][:5],
    )
    if s.p_value > SIGNIFICANCE:
        out.kind, out.meaning = "model_change", "no hypothesis explains the change significantly"
        return out
    if out.kind == "thruster_loss":
        out.thruster = s.name.split(".", 1)[1]
        out.efficiency = float(np.clip(1.0 - s.delta, 0.0, 1.0))
        lo, hi = 1.0 - s.delta - 1.96 * s.stderr, 1.0 - s.delta + 1.96 * s.stderr
        out.efficiency_interval = (float(np.clip(lo, 0, 1)), float(np.clip(hi, 0, 1)))
    else:
        out.effect, out.value, out.stderr = s.name, float(s.value), float(s.stderr)
    return out


def _wrench(parts: list, ws, rows: int, rss: float, scored: list, post: np.ndarray) -> Diagnosis:
    """A constant external force and moment in several DOFs, fitted jointly: the residual
    variance is the joint fit's (each part's own screen saw the others' force as noise); named
    by its largest component, every significant component in ``wrench``."""
    drss = sum(s.drss for s in parts)
    n = rows * len(ws.dofs)
    sigma2 = max(rss - drss, 1e-300) / max(n - len(parts), 1)
    n_eff = max(n / ws.tau_corr - len(parts), 1.0)
    comps = {}
    for s in parts:
        se = s.stderr * np.sqrt(sigma2 / s.sigma2)
        p_value = float(f_dist.sf((s.value / se) ** 2, 1, n_eff)) if se > 0 else 0.0
        if p_value <= SIGNIFICANCE:
            comps[s.name.split(".")[1]] = {"value": float(s.value), "stderr": float(se)}
    main = max(parts, key=lambda s: s.drss)
    dof = main.name.split(".")[1]
    return Diagnosis(
        "external_force",
        effect=main.name,
        value=float(main.value),
        stderr=comps.get(dof, {"stderr": float(main.stderr)})["stderr"],
        confidence=float(post[-1]),
        explained=float(drss / rss) if rss > 0 else 0.0,
        p_value=float(main.p_value),
        meaning="a constant external force and moment (tether, collision): "
        + ", ".join(f"{d} {c['value']:.3g} ± {c['stderr']:.2g}" for d, c in comps.items()),
        wrench=comps,
        alternatives=[
            {"hypothesis": s.name, "posterior": float(p)}
            for s, p in zip(scored, post, strict=False)
        ][:5],
    )


def _kind(s) -> str:
    if s.candidate.kind == "thruster_loss":
        return "thruster_loss"
    return "external_force" if s.candidate.kind == "external_bias" else "model_change"
