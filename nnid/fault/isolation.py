"""Isolation and estimation: which thruster or which effect a change is, and how large.

On the window after an alarm, the force residual r of the monitor is explained in turn by each
hypothesis, with the residual loop's own scoring (:func:`nnid.loop.diagnose.screen`: the exact
one-column least-squares refit, its F-test with the residual's correlation time, the standard
error) and the loop's own candidates (:func:`nnid.loop.effects.candidates`, their regressor
columns from :class:`nnid.models.parametric.ParametricFossen`): one implementation of "name the
effect". The fault hypotheses added here are the thrusters: thruster i losing a fraction s of its
thrust leaves r = −s cᵢ, cᵢ = η(Bf) − η(Bf − bᵢfᵢ) the force the kernel's nominal force loses
with it stopped (bᵢ its allocation column, fᵢ its thrust past the deadband, η the installation
coefficients by the sign of each DOF's force; ≈ η bᵢ fᵢ), so its column is cᵢ and its remaining
efficiency is 1 − s.

Kinds: ``thruster_loss`` (a thruster), ``external_force`` (``external_bias.<dof>``: a constant
force such as a tether snag) and ``model_change`` (any other effect: ``buoyancy_offset`` for a
payload, ``added_mass.<dof>``, damping). A thruster's signature follows its command, an external
force is constant in the body frame, a buoyancy change follows the attitude. Two hypotheses of
several parameters join the one-parameter ones, weighed by penalised likelihood (BIC): a
constant external force and moment in every DOF watched (a tether pulling at a point off the
centre), and a payload (its weight minus buoyancy with its mass in the translational added
masses). Hypotheses whose whitened columns are nearly parallel on the window cannot be told
apart by the data; among them the physically likelier is named (a thruster, then a buoyancy
change: a vertical constant force on a level vehicle is a ballast change more often than a
tether pulling down), and the confidence is the posterior weight of the whole group, so it says
how sure the *group* is.
"""

from __future__ import annotations

import warnings
from collections.abc import Collection
from dataclasses import dataclass, field
from itertools import pairwise
from types import SimpleNamespace

import numpy as np
import pandas as pd
from scipy.special import lambertw
from scipy.stats import f as f_dist

from nnid.datasets.log import POSE, TAU, VELOCITY
from nnid.datasets.preprocess import (
    piece_window,
    savgol_derivative,
    savgol_window,
    step_window,
)
from nnid.loop.diagnose import Fit, screen
from nnid.loop.effects import Candidate, candidates
from nnid.models.parametric import ParametricFossen, vehicle_with
from nnid.physics.thrusters import Actuation, apply_deadband, apply_installation
from nnid.reports.cells import number
from nnid.trainers.least_squares import feasible_floor, feasible_weights

_PRIORITY = {"thruster_loss": 0, "buoyancy_offset": 1, "external_bias": 2}
PARALLEL = 0.95  # |cos| of whitened columns above which two hypotheses are one to the data
#: the family-wise level a hypothesis is named at: its p-value Bonferroni-adjusted over the
#: hypotheses screened (:func:`adjusted`) at most this
SIGNIFICANCE = 0.01
#: the hypothesis that nothing changed, as the alternatives name it beside the changes
NO_CHANGE = "no change"
#: what an alarm says where no hypothesis (one parameter or joint) passes :data:`SIGNIFICANCE`
NOT_SIGNIFICANT = "no hypothesis explains the change significantly"
#: what an alarm says where the best hypothesis leaves more than :data:`UNEXPLAINED_RATIO`
UNEXPLAINED = "unexplained by the hypotheses"
#: the fewest rows with a finite residual that isolation fits (:func:`isolate`, :func:`refit`);
#: an alarm with fewer after it is said :data:`TOO_FEW`, not judged
LEAST_ROWS = 10
#: what an alarm says where its window holds fewer than :data:`LEAST_ROWS` rows to isolate on
TOO_FEW = "too few samples after the alarm to isolate"
# the largest mean square of the whitened residual, in units of the healthy noise power, that
# a named hypothesis may leave: twice the noise, i.e. as much unexplained power as the noise
# itself. The one right hypothesis left at most 1.48 over 59 alarms of simulated single faults,
# reversed thrusters aside (the monitor's model error grows with the fault: a stopped thruster
# flies the vehicle out of the fitted envelope); two thrusters lost at once left 2.8-38. Not a
# χ² test against 1: on 10 s (1,200 whitened samples) its 1 % level is 1.1, and correct
# hypotheses left up to 1.48.
UNEXPLAINED_RATIO = 2.0
# and more than this share of the residual's excess over the noise: the model error left after
# the right hypothesis grows with the fault (a thruster pushing against its command left 720
# times the noise of a residual 10⁵ times it; the right hypotheses left under 1 % of large
# excesses, two faults at once 3-80 %)
UNEXPLAINED_SHARE = 0.02
# a stopped thruster's efficiency is estimated a few % below zero on the simulated 8-thruster
# vehicle (the monitor's model error, not in the interval): that far under 0 is a stopped
# thruster; further, the thruster pushes against its command
STOPPED_SLACK = 0.1


@dataclass
class Diagnosis:
    """What changed: ``kind``, the ``thruster`` and its ``efficiency`` (with a 95 % interval),
    or the ``effect`` with its ``value`` and ``stderr`` (and, for a hypothesis of several
    parameters, every significant one in ``components``); ``confidence`` the posterior weight
    (BIC, among the hypotheses and no change at all) of the named hypothesis and those the
    data cannot tell from it, None where none is named (:func:`_none_named`; or none was
    fitted); ``explained`` the share of the whitened residual the fitted hypothesis explains,
    None where none was fitted (too few rows, or no hypothesis has a signature on the window:
    a 0 there was not measured); ``p_value`` its F-test's, Bonferroni-adjusted over the
    hypotheses screened (:func:`adjusted`); ``alternatives`` the next ones, no change
    (:data:`NO_CHANGE`) among them."""

    kind: str
    thruster: str | None = None
    efficiency: float | None = None
    efficiency_interval: tuple[float, float] | None = None
    effect: str | None = None
    value: float | None = None
    stderr: float | None = None
    confidence: float | None = None
    explained: float | None = None
    p_value: float | None = None
    meaning: str = ""
    alternatives: list[dict] = field(default_factory=list)
    components: dict[str, dict[str, float]] | None = None  # of a joint hypothesis
    residual_ratio: float | None = None  # what the named hypothesis leaves, in noise power
    hypothesis: str | None = None  # the best-fitting hypothesis, named or not
    fitted: list[tuple[str, float]] = field(default_factory=list)  # its columns and θ
    isolated: bool = False  # a hypothesis named that explains the change (kind, size)


def fitted_vehicle(plant):
    """The monitor's model as a vehicle file: its vehicle with the fitted values written in;
    the vehicle itself, said in a warning, where a parameter is not the vehicle file's or a
    value is refused (:func:`~nnid.models.parametric.vehicle_with`). Any other error is a
    defect and raised: caught as every exception, it was silent, and the effects' values were
    then converted against the file's values, not the model's."""
    values = {k: v["value"] for k, v in plant.params.items() if v.get("value") is not None}
    try:
        return vehicle_with(plant.vehicle, values)
    except (KeyError, IndexError, ValueError) as err:  # a name or a value the file has not
        warnings.warn(
            f"the monitor's fitted values could not be written into vehicle "
            f"'{plant.vehicle.name}' ({err}): isolation sizes the effects against the vehicle "
            "file's values, not the model's",
            stacklevel=2,
        )
        return plant.vehicle


def midpoint_data(
    data: dict,
    rows: np.ndarray,
    vehicle,
    savgol: tuple[float, int] = (0.5, 2),
    act: Actuation | None = None,
    clock: tuple[float, float] | None = None,
) -> dict:
    """The arrays of the intervals ending at ``rows`` as the regression sees them: pose and
    velocity at the midpoint, the force of the commands held over the interval, and the
    acceleration by a Savitzky-Golay derivative (``savgol``: window in seconds, order). Not the
    difference quotient the residual is made of: a column built from the same noisy
    difference would "explain" the residual's own noise (errors in variables; an added-mass
    column then comes out near the vehicle's whole mass on a healthy window). ``act``: the
    ``vehicle``'s :class:`~nnid.physics.thrusters.Actuation` where the caller keeps one;
    ``clock``: the monitor's calibrated sample interval and the longest it gives a residual
    (:func:`smoothing_window`), the derivative cut at a longer one."""
    x, x0 = data["x"][rows], data["x"][rows - 1]
    mid = 0.5 * (x + x0)
    step = x[:, 3:6] - x0[:, 3:6]
    step -= 2 * np.pi * np.floor((step + np.pi) / (2 * np.pi))
    mid[:, 3:6] = x0[:, 3:6] + 0.5 * step
    span = np.arange(rows[0] - 1, rows[-1] + 1)
    t = data["t"][span]
    dt, window = smoothing_window(t, savgol, clock)
    longest = np.inf if clock is None else clock[1]
    acc = np.full((span.size, 6), np.nan)
    # a stretch between two intervals too long for a residual (samples missing) on its own,
    # as the monitor scores none across them: a window across one reads no acceleration
    cuts = [0, *(np.flatnonzero(np.diff(t) > longest) + 1), span.size]
    for a, b in pairwise(cuts):
        w = piece_window(b - a, window)
        if w > savgol[1]:
            vel = data["x"][span[a:b], 6:12]
            acc[a:b] = np.column_stack(
                [savgol_derivative(vel[:, j], dt, w, savgol[1]) for j in range(6)]
            )
        elif b - a == 2:  # two samples: their slope
            acc[a:b] = (data["x"][span[a + 1], 6:12] - data["x"][span[a], 6:12]) / dt
    at = rows - span[0]
    act = Actuation(vehicle) if act is None else act
    inputs = data["inputs"][rows - 1]
    return {
        "eta": mid[:, 0:6],
        "nu": mid[:, 6:12],
        "nu_dot": 0.5 * (acc[at] + acc[at - 1]),
        "tau": act.nominal(inputs) if act.thrusters else inputs,
        "angles_known": np.array(True),
        "t": 0.5 * (data["t"][rows] + data["t"][rows - 1]),
        "experiment": np.zeros(rows.size, dtype=int),
        "experiment_names": np.array(["window"], dtype=object),
    }


def smoothing_window(
    t: np.ndarray, savgol: tuple[float, int], clock: tuple[float, float] | None = None
) -> tuple[float, int]:
    """The step and the samples of :func:`midpoint_data`'s Savitzky-Golay derivative on a
    span of times ``t``: ``savgol``'s window in seconds at the rate of ``clock``'s interval
    (the monitor's calibrated one, :attr:`~nnid.fault.monitor.ResidualMonitor.interval`; None:
    the span's typical step, :func:`~nnid.datasets.preprocess.step_window`), at most the span
    (odd, :func:`~nnid.datasets.preprocess.piece_window`). Not the span's median step: on a
    clock alternating 0.04 and 0.06 s it is 0.04, 0.05 or 0.06 by one sample more or less,
    and --follow's half-second spans read another acceleration than batch's rest of the run.
    Its last half window is evaluated off-centre, the window's polynomial extrapolated
    (:func:`~nnid.datasets.preprocess.savgol_interp`)."""
    if clock is None:
        dt, window = step_window(t, *savgol, np.nan)
    else:
        dt, window = clock[0], savgol_window(savgol[0], 1.0 / clock[0], savgol[1])
    return dt, piece_window(t.size, window)


def midpoint_frame(arrays: dict) -> pd.DataFrame:
    """:func:`midpoint_data`'s arrays as the log frame the loop's candidates read."""
    values = np.concatenate([arrays["eta"], arrays["nu"], arrays["tau"]], 1)
    frame = pd.DataFrame(values, columns=[*POSE, *VELOCITY, *TAU])
    frame.insert(0, "t", arrays["t"])
    return frame


class Hypotheses:
    """The hypotheses of a monitor's model (the loop's linear candidates and one per thruster),
    only those in ``names`` where given, and what their columns need that depends on the
    model alone: the fitted vehicle, its actuation, which candidates, the regression. Made
    once, their :meth:`columns` are taken on any rows: --follow takes a change's signature
    out of every flush (:class:`~nnid.fault.detect.Rewatch` keeps one per change), where
    remaking these cost about as much as the columns."""

    def __init__(self, monitor, names: Collection[str] | None = None) -> None:
        plant = monitor.plant_
        self.plant = plant
        self.names = None if names is None else frozenset(names)
        self.vehicle = fitted_vehicle(plant)
        self.savgol = (plant.savgol_window, 2)
        self.clock = (float(monitor.interval), float(monitor.max_interval))
        self.act = Actuation(plant.vehicle)
        # the installation and deadband the monitor's kernel maps commands through
        # (:func:`~nnid.fault.monitor.pack_actuation`): the model's η, the vehicle's deadband
        self.eta = tuple(
            np.asarray(e, dtype=np.float64) for e in (plant.parts_.eta_pos, plant.parts_.eta_neg)
        )
        self.deadband = float(plant.vehicle.deadband)
        self.fitted_act = Actuation(self.vehicle)  # the midpoint data's nominal force
        self.own = [Candidate(f"thruster_loss.{n}", "thruster_loss", f"thruster.{n}")
                    for n in self.act.channels] if self.act.thrusters else []  # fmt: skip
        # thrusters alone (a lost thruster's signature) need none of the loop's columns:
        # their midpoint data and candidates were most of its cost
        self.loop = self.names is None or not self.names <= {c.name for c in self.own}
        self._cands: list[Candidate] | None = None  # the loop's, once rows show them
        self._structure: ParametricFossen | None = None
        self._inertial: bool | None = None  # :meth:`reads_acceleration`, once asked

    @classmethod
    def reused(cls, made: Hypotheses | None, monitor, names: Collection[str] | None) -> Hypotheses:
        """``made`` where it holds ``monitor``'s model's hypotheses ``names``, else new ones
        (a change taken out, ended or resized names others; a model refitted is another)."""
        named = None if names is None else frozenset(names)
        if made is not None and made.plant is monitor.plant_ and made.names == named:
            return made
        return cls(monitor, names)

    def columns(self, data: dict, rows: np.ndarray) -> tuple:
        """The fitted vehicle, the hypotheses and their columns [N, 6, K] on ``rows`` (each
        with its predecessor)."""
        cands, cols = [], np.zeros((rows.size, 6, 0))
        if self.loop:
            arrays = midpoint_data(
                data, rows, self.vehicle, self.savgol, self.fitted_act, self.clock
            )
            if self._cands is None:
                # the thrusters themselves stand for thrust changes; a DOF's installation
                # coefficient would only be a coarser copy of them. Which of the others are
                # linear depends on the vehicle alone (the rows choose only installation
                # directions and the nonlinear ones), so the first rows' choice holds for all
                self._cands = [
                    c
                    for c in candidates(self.vehicle, midpoint_frame(arrays), coupled=False)
                    if c.linear
                    and c.kind != "thruster_installation"
                    and (self.names is None or c.name in self.names)
                ]
                if self._cands:
                    params = [c.parameter for c in self._cands]
                    self._structure = ParametricFossen(self.vehicle, params)
            cands = list(self._cands)
            if self._structure is not None:
                reg = self._structure.regression(arrays)
                cols = reg.phi.reshape(rows.size, 6, len(cands))
        if self.own:
            cols = np.concatenate([cols, self.thruster_columns(data["inputs"][rows - 1])], 2)
            cands += self.own
        return self.vehicle, cands, cols

    def thruster_columns(self, inputs: np.ndarray) -> np.ndarray:
        """Each thruster's column [N, 6, n] for the commands ``inputs`` [N, n] held: the
        force the residual's nominal force loses with that thruster stopped, as the kernel
        makes it (:func:`nnid.fault.kernel._force`: deadband, curve, allocation, then the
        model's installation coefficients η by the sign of each DOF's force), η(Bf) − η(Bf −
        bᵢfᵢ). Without η and the deadband (bᵢfᵢ), a thruster stopped where η is 0.56 was read
        at 44 % of its thrust, and one whose command sat in the deadband was said lost."""
        thrust = self.act.thrusts(apply_deadband(inputs, self.deadband))  # [N, n]
        tau = thrust @ self.act.matrix.T  # [N, 6]
        without = tau[:, :, None] - thrust[:, None, :] * self.act.matrix[None, :, :]
        eta_pos, eta_neg = self.eta[0][:, None], self.eta[1][:, None]
        whole = apply_installation(tau, *self.eta)
        return whole[:, :, None] - apply_installation(without, eta_pos, eta_neg)

    def reads_acceleration(self) -> bool:
        """Whether a column of these hypotheses, as :meth:`columns` made them, reads the
        acceleration: its unit changes the mass matrix (an added mass, a payload's; the
        centre of gravity's height, which M_RB couples to the accelerations)."""
        if self._structure is None:  # no column of the loop's made yet (thrusters only)
            return False
        if self._inertial is None:
            s = self._structure
            base = s.parts({}).model(check=False).mass_matrix().numpy()
            self._inertial = any(
                not np.array_equal(s.parts({n: 1.0}).model(check=False).mass_matrix().numpy(), base)
                for n in s.names
            )
        return self._inertial

    def extrapolated(self, data: dict, rows: np.ndarray) -> np.ndarray:
        """Which of ``rows`` (as :meth:`columns` takes them) have columns read off the
        acceleration's extrapolated end, [rows] bool: the span's last half smoothing window
        (:func:`smoothing_window`) where a column reads the acceleration
        (:meth:`reads_acceleration`), none elsewhere."""
        out = np.zeros(rows.size, dtype=bool)
        if rows.size and self.reads_acceleration():
            span = data["t"][max(rows[0] - 1, 0) : rows[-1] + 1]  # as midpoint_data's
            half = smoothing_window(span, self.savgol, self.clock)[1] // 2
            out[rows.size - min(half, rows.size) :] = True
        return out


def hypothesis_columns(monitor, data: dict, rows: np.ndarray, names=None) -> tuple:
    """The fitted vehicle, the hypotheses (the loop's linear candidates and one per thruster)
    and their columns [N, 6, K] on ``rows`` (each with its predecessor); only those named in
    ``names`` where given (a signature needs its own columns, not the ~15 regressions of all)."""
    return Hypotheses(monitor, names).columns(data, rows)


def dof_weights(monitor, e: np.ndarray) -> np.ndarray:
    """Each DOF equation's weight [6] in isolation's least squares of the residual ``e``
    [N, 6] (μ taken out, NaN where a row is not fitted): 1/σ² of the monitor's healthy
    residual on the DOFs it watches (0 on the others), σ² at least feasible weighting's floor
    (:func:`~nnid.trainers.least_squares.feasible_floor`, ``e`` its targets). Unfloored, a DOF
    of exact data (σ ~0) took a weight of 1e16 or more that swamped the other DOFs, or an
    infinite one, and no hypothesis had a signature."""
    watched = monitor.mask_ > 0
    var = np.where(watched, monitor.sigma_**2, np.nan)
    floor = feasible_floor(var, np.where(watched, e, np.nan).reshape(-1), 6)
    return np.where(watched, feasible_weights(var, floor), 0.0)


def signature(
    monitor,
    data: dict,
    rows: np.ndarray,
    fitted: list[tuple[str, float]],
    hypotheses: Hypotheses | None = None,
):
    """The residual an isolated change leaves on ``rows`` [N, 6] (NaN where there is none):
    minus the fitted hypothesis' columns times their θ (:attr:`Diagnosis.fitted`). Taken from
    the residual, it leaves what a model *with* that change would leave. ``hypotheses``:
    those of ``fitted`` made before (:class:`Hypotheses`), else made here."""
    out = np.full((rows.size, 6), np.nan)
    ok = rows > 0
    if ok.sum() < 2 or not fitted:
        return out
    hypotheses = Hypotheses.reused(hypotheses, monitor, {name for name, _ in fitted})
    _, cands, cols = hypotheses.columns(data, rows[ok])
    index = {c.name: k for k, c in enumerate(cands)}
    if any(name not in index for name, _ in fitted):
        return out  # a hypothesis the rows cannot show (a DOF that no longer moves)
    out[ok] = -sum(theta * cols[:, :, index[name]] for name, theta in fitted)
    return out


def fits_rows(rows: np.ndarray, residual: np.ndarray) -> np.ndarray:
    """Which of ``rows`` isolation fits, [rows] bool: each with its predecessor and a finite
    ``residual`` [rows, 6] (a row of a sensor dropout, or not judged at a run's end, has
    none); fewer than :data:`LEAST_ROWS` of them and nothing is judged (:data:`TOO_FEW`)."""
    return (rows > 0) & np.isfinite(residual).all(1)


def isolate(
    monitor, data: dict, residual: np.ndarray, rows: np.ndarray, taken: list = ()
) -> Diagnosis:
    """Name the change behind the monitor's residual ``residual`` [N, 6] on ``rows`` (indices
    into ``data`` of :func:`nnid.fault.monitor.monitor_inputs`, each with its predecessor).
    ``taken``: the changes already taken out of that residual (:attr:`Diagnosis.fitted` of
    earlier alarms): a thruster's efficiency is stated against its nominal thrust, not against
    the model those changes make (a thruster at 30 % that recovers is 100 % of nominal, where
    the change on top of the 30 % reads 170 %)."""
    plant = monitor.plant_
    rows = rows[fits_rows(rows, residual[rows])]
    if rows.size < LEAST_ROWS:
        return Diagnosis("model_change", meaning=TOO_FEW)
    vehicle, cands, cols = hypothesis_columns(monitor, data, rows)
    e = residual[rows] - monitor.mu_
    weights = dof_weights(monitor, e)
    ws = SimpleNamespace(weights=weights, dofs=plant.dofs_, tau_corr=monitor.correlation_time_)
    empty = np.zeros((rows.size, 6, 0))
    rss = float(np.sum(e**2 * weights))
    fit = Fit(vehicle, [], np.zeros(0), np.zeros(0), empty, empty, e, e, rss)
    with np.errstate(invalid="ignore", divide="ignore"):
        # screen names a hypothesis whose column is zero on the window (a thruster not run)
        # or adds no direction: nothing of it is measured, so it has no posterior either
        scored = [s for s in screen(ws, fit, cands, cols, cols) if s.scored]
    if not scored:
        return Diagnosis("model_change", meaning="no hypothesis has a signature on this window")
    scored.sort(key=lambda s: -s.drss)
    index = {c.name: k for k, c in enumerate(cands)}
    # penalised log-likelihood (BIC) of the one-parameter hypotheses and of the two joint ones
    n_eff = rows.size * len(plant.dofs_) / ws.tau_corr
    penalty = 0.5 * np.log(max(n_eff, 2.0))
    logl = np.array([profile_logl(s.drss, rss, n_eff) for s in scored]) - penalty
    wrench = [f"external_bias.{d}" for d in plant.dofs_]
    payload = ["buoyancy_offset", *(f"added_mass.{d}" for d in "uvw")]
    joint = [_joint("external_force", wrench, cands, cols, e, ws, penalty)]
    joint = [j for j in [*joint, _joint("model_change", payload, cands, cols, e, ws, penalty)] if j]
    # and nothing changed (log-likelihood 0, no parameter): without it the posterior was
    # shared among changes only, and read 1.00 where BIC preferred no change at all
    every = np.r_[logl, [j.logl for j in joint], 0.0]
    post = np.exp(every - every.max())
    post /= post.sum()
    null = float(post[-1])
    # the best of K hypotheses is tested: Bonferroni over the hypotheses screened, so that
    # healthy noise names one at SIGNIFICANCE, not at K times it (~30 tried)
    tried = len(scored) + len(joint)
    alternatives = _ranked([s.name for s in scored], post[: len(scored)], null)
    if joint and max(j.logl for j in joint) > logl.max():
        k = int(np.argmax([j.logl for j in joint]))
        j = joint[k]
        posterior = float(post[len(scored) + k])
        out = j.diagnosis(posterior, rss, vehicle, alternatives, tried)
        pick = [index[c.name] for c in j.members]
        out.fitted = [(c.name, float(t)) for c, t in zip(j.members, j.theta, strict=True)]
        out.hypothesis = j.kind if j.kind == "external_force" else "payload"
        if _unexplained(out, monitor, e, e + cols[:, :, pick] @ j.theta) or (
            out.meaning == NOT_SIGNIFICANT
        ):
            out.isolated = False
            _none_named(out, posterior)
        return out
    post = post[: len(scored)]
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
        p_value=adjusted(s.p_value, tried),
        meaning=s.candidate.meaning,
        alternatives=_ranked([c.name for c in scored], post, null, skip=s.name),
    )
    out.fitted, out.hypothesis = [(s.name, float(s.delta))], s.name
    if _unexplained(out, monitor, e, e + s.delta * cols[:, :, index[s.name]]):
        _none_named(out, float(post[named]))
        return out
    if out.p_value > SIGNIFICANCE:
        out.kind, out.meaning, out.isolated = "model_change", NOT_SIGNIFICANT, False
        _none_named(out, float(post[named]))
        return out
    if out.kind == "thruster_loss":
        out.thruster = s.name.split(".", 1)[1]
        # the thruster's columns are the force it gives at nominal thrust, so the losses taken
        # out before add to this one: its efficiency against nominal is 1 minus their sum
        eff = float(1.0 - s.delta - sum(theta for name, theta in taken if name == s.name))
        lo, hi = eff - 1.96 * s.stderr, eff + 1.96 * s.stderr
        if hi >= -STOPPED_SLACK and lo <= 1.0:  # a loss the interval allows: said so
            out.efficiency = float(np.clip(eff, 0.0, 1.0))
            out.efficiency_interval = (float(np.clip(lo, 0, 1)), float(np.clip(hi, 0, 1)))
        else:  # more thrust than nominal, or reversed: a change, not a loss, and said as one
            out.efficiency, out.efficiency_interval = eff, (lo, hi)
            out.kind = "model_change"
            out.meaning = (
                f"thruster {out.thruster} gives more thrust than nominal"
                if eff > 1.0
                else f"thruster {out.thruster} pushes against its command (thrust reversed)"
            )
    else:
        out.effect, out.value, out.stderr = s.name, float(s.value), float(s.stderr)
    return out


@dataclass
class _Joint:
    """A hypothesis of several parameters fitted together: a constant external force and
    moment (``external_force``: the external_bias of every DOF watched), or a changed vehicle
    (``model_change``: a payload's weight minus buoyancy with its mass in the translational
    added masses)."""

    kind: str
    members: list  # the candidates
    theta: np.ndarray
    stderr: np.ndarray
    p_values: np.ndarray
    drss: float
    logl: float

    def diagnosis(
        self, posterior: float, rss: float, vehicle, alternatives: list, tried: int = 1
    ) -> Diagnosis:
        """What the fit says (``posterior`` its weight, ``rss`` the residual's, ``tried`` the
        hypotheses screened beside it: its members' p-values are :func:`adjusted` over them)."""
        p_values = np.array([adjusted(p, tried) for p in self.p_values])
        values = [c.value(float(t), vehicle) for c, t in zip(self.members, self.theta, strict=True)]
        ses = [
            float(se * abs(c.value_scale(vehicle)))
            for c, se in zip(self.members, self.stderr, strict=True)
        ]
        keep = [k for k, p in enumerate(p_values) if p <= SIGNIFICANCE]
        if not keep:  # as the one-parameter path says it: no member is significant
            return Diagnosis(  # its posterior goes among the alternatives (_none_named)
                "model_change",
                explained=self.drss / rss if rss > 0 else 0.0,
                meaning=NOT_SIGNIFICANT,
                alternatives=alternatives,
            )
        names = [c.name for c in self.members]
        # the buoyancy change heads a payload where it is significant (a non-significant one
        # headed it: "buoyancy_offset = 2.67 ± 1.5, p 0.079"), else the clearest member
        main = (
            names.index("buoyancy_offset")
            if "buoyancy_offset" in names and names.index("buoyancy_offset") in keep
            else max(keep, key=lambda k: abs(self.theta[k]) / max(self.stderr[k], 1e-300))
        )
        components = {self.members[k].name: {"value": values[k], "stderr": ses[k]} for k in keep}
        what = (
            "a constant external force and moment (tether, collision)"
            if self.kind == "external_force"
            else "the vehicle changed (payload: weight, buoyancy and mass)"
        )
        return Diagnosis(
            self.kind,
            effect=self.members[main].name,
            value=values[main],
            stderr=ses[main],
            confidence=posterior,
            explained=self.drss / rss if rss > 0 else 0.0,
            p_value=float(p_values[main]),
            meaning=what
            + ": "
            + ", ".join(
                f"{n} {number(c['value'], 3)} ± {number(c['stderr'], 2)}"
                for n, c in components.items()
            ),
            components=components,
            alternatives=alternatives,
        )


def _joint(
    kind: str, names: list[str], cands: list, cols: np.ndarray, e: np.ndarray, ws, penalty: float
) -> _Joint | None:
    """Weighted least squares of the residual on the columns of ``names`` together (those of
    them that are candidates; None when fewer than two are)."""
    pick = [k for k, c in enumerate(cands) if c.name in names]
    if len(pick) < 2:
        return None
    w = np.sqrt(ws.weights)
    a = (cols[:, :, pick] * w[None, :, None]).reshape(-1, len(pick))
    y = -(e * w[None, :]).ravel()
    keep = np.abs(a).sum(0) > 0
    if keep.sum() < 2:
        return None
    pick = [k for k, ok in zip(pick, keep, strict=True) if ok]
    a = a[:, keep]
    theta, *_ = np.linalg.lstsq(a, y, rcond=None)
    resid = y - a @ theta
    drss = float(y @ y - resid @ resid)
    n = e.shape[0] * len(ws.dofs)
    sigma2 = float(resid @ resid) / max(n - len(pick), 1)
    cov = sigma2 * ws.tau_corr * np.linalg.pinv(a.T @ a)
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    n_eff = max(n / ws.tau_corr - len(pick), 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        p_values = f_dist.sf(np.where(se > 0, (theta / se) ** 2, np.inf), 1, n_eff)
    logl = profile_logl(drss, float(y @ y), n / ws.tau_corr) - len(pick) * penalty
    return _Joint(kind, [cands[k] for k in pick], theta, se, p_values, drss, logl)


@dataclass
class Refit:
    """Hypotheses fitted together on some rows (:func:`refit`): ``fits`` per name, its
    ``theta`` (the change of its parameter, 0: none), standard error ``se`` (with the
    residual's correlation time), and ``value`` and ``value_se`` in the effect's own units (a
    thruster's θ is the share of its nominal thrust lost); ``cov`` the covariance of the θ
    (in the order of ``fits``), ``n_eff`` the independent samples behind it, ``p_value`` the
    F-test of all θ being 0 (none of the hypotheses on these rows), and ``left`` [rows, 6] the
    residual with the fitted hypotheses taken out."""

    fits: dict[str, dict[str, float]]
    cov: np.ndarray
    n_eff: float
    left: np.ndarray

    @property
    def p_value(self) -> float:
        """The F-test of all θ being 0: :meth:`p_differs` from none of the hypotheses."""
        return self.p_differs(np.zeros(len(self.fits)))

    def p_differs(self, theta: np.ndarray) -> float:
        """The F-test of the fitted θ against ``theta`` (same order): small where the rows
        show another size than ``theta``."""
        d = np.array([f["theta"] for f in self.fits.values()]) - np.asarray(theta, float)
        wald = float(d @ np.linalg.pinv(self.cov) @ d)
        return float(f_dist.sf(wald / d.size, d.size, self.n_eff))


def refit(
    monitor, data: dict, residual: np.ndarray, rows: np.ndarray, names: list[str]
) -> Refit | None:
    """The hypotheses ``names`` (columns of :func:`hypothesis_columns`) fitted together to the
    residual ``residual`` [len(rows), 6] of ``rows`` by :func:`isolate`'s weighted least
    squares (:class:`Refit`). None where, of the rows with a finite residual, fewer than
    :data:`LEAST_ROWS` are left or a hypothesis has no column on them."""
    keep = fits_rows(rows, residual)
    rows, residual = rows[keep], residual[keep]
    if rows.size < LEAST_ROWS:
        return None
    vehicle, cands, cols = hypothesis_columns(monitor, data, rows, set(names))
    index = {c.name: k for k, c in enumerate(cands)}
    if any(name not in index for name in names):
        return None
    pick = [index[name] for name in names]
    e = residual - monitor.mu_
    w = np.sqrt(dof_weights(monitor, e))  # isolate's weights
    a = (cols[:, :, pick] * w[None, :, None]).reshape(-1, len(pick))
    y = -(e * w[None, :]).ravel()
    theta, *_ = np.linalg.lstsq(a, y, rcond=None)
    resid = y - a @ theta
    n = rows.size * len(monitor.plant_.dofs_)
    sigma2 = float(resid @ resid) / max(n - len(pick), 1)
    cov = sigma2 * monitor.correlation_time_ * np.linalg.pinv(a.T @ a)
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    n_eff = max(n / monitor.correlation_time_ - len(pick), 1.0)  # as :func:`_joint` has it
    out = {}
    for name, k, t, e in zip(names, pick, theta, se, strict=True):
        c = cands[k]
        thruster = c.kind == "thruster_loss"
        value = float(t) if thruster else float(c.value(float(t), vehicle))
        scale = 1.0 if thruster else abs(c.value_scale(vehicle))
        out[name] = {"theta": float(t), "se": float(e), "value": value,
                     "value_se": float(e * scale)}  # fmt: skip
    left = residual + cols[:, :, pick] @ theta  # minus the signature (:func:`signature`)
    return Refit(out, cov, n_eff, left)


def whitened_power(monitor, e: np.ndarray) -> np.ndarray:
    """The square of each coordinate of the residual ``e`` [N, 6] (μ taken out) whitened by
    the monitor's healthy covariance, on its rows that are finite: [rows, 6], the power that
    :func:`noise_ratio` and :func:`dof_noise_ratios` average."""
    e = e[np.isfinite(e).all(1)]
    return (e @ monitor.whiten_.T) ** 2


def noise_ratio(monitor, e: np.ndarray) -> float:
    """Mean square of the residual ``e`` [N, 6] (μ taken out) whitened by the monitor's
    healthy covariance: 1 is the healthy noise level; NaN where no row of ``e`` is finite
    (nothing measured, not "no excess"). :func:`dof_noise_ratios`' mean over the DOF equations
    watched, but summed over every value at once (their mean, summed DOF by DOF first, differs
    in the last bit)."""
    power = whitened_power(monitor, e)
    if power.shape[0] == 0:
        return np.nan
    dim = float(monitor.mask_.sum())
    return float(np.sum(power)) / max(power.shape[0] * dim, 1.0)


def dof_noise_ratios(monitor, e: np.ndarray) -> np.ndarray:
    """:func:`noise_ratio` of each DOF equation [6]: the mean square of each coordinate of the
    whitened residual ``e`` [N, 6] (μ taken out; the whitening is triangular, so coordinate j
    is DOF j's equation less what the DOFs before it predict of its noise); 0 on a DOF the
    monitor does not watch; NaN on every DOF where no row of ``e`` is finite."""
    power = whitened_power(monitor, e)
    if power.shape[0] == 0:
        return np.full(power.shape[1], np.nan)
    return np.sum(power, axis=0) / power.shape[0]


def model_error(baseline: float) -> float:
    """The power of the model's error, in units of the healthy noise power, in a residual whose
    noise ratio is ``baseline``: :data:`UNEXPLAINED_SHARE` of its excess over the noise (the
    model's error grows with the fault)."""
    return UNEXPLAINED_SHARE * (baseline - 1.0)


def allowed_ratio(baseline: float | np.ndarray) -> float | np.ndarray:
    """The most a named hypothesis may leave (its :func:`noise_ratio`) of a residual whose
    noise ratio is ``baseline`` (a number, or an array of them): :data:`UNEXPLAINED_RATIO`,
    or where more, the noise and :func:`model_error`. The one rule of isolation, of a later
    alarm explained by the changes taken out, and of a change that ended or changed size; each
    caller names its baseline (1, the healthy noise, where no fault is left: no share)."""
    allowed = np.maximum(UNEXPLAINED_RATIO, 1.0 + model_error(baseline))
    return float(allowed) if np.ndim(allowed) == 0 else allowed


def allowed_over(n_dofs: int, dim: float) -> float:
    """What a hypothesis may leave of the healthy noise (:func:`allowed_ratio` of 1) in a noise
    ratio averaged over ``n_dofs`` of the ``dim`` DOF equations watched, as unlikely from
    healthy noise as :func:`allowed_ratio` of 1 is over all ``dim``. Healthy, the ratio over n
    equations of N rows is χ² of n·N/τ independent samples over its count, whose tail above x
    falls as exp(−n·N/(2τ)·(x − 1 − ln x)) (Chernoff): the level x where that exponent equals
    the one of the full ratio, whatever N and τ (2 over 6 DOF equations: 2.12 over 5, 2.55 over
    3, 4.30 over 1). A fixed level is crossed more easily over fewer equations: their mean
    spreads more."""
    if n_dofs < 1:
        raise ValueError(f"allowed_over needs at least one DOF equation, got {n_dofs}")
    a = allowed_ratio(1.0)
    rate = dim / n_dofs * (a - 1.0 - np.log(a))
    # x − ln x = 1 + rate, x > 1: the lower real branch of Lambert's W
    return float(-lambertw(-np.exp(-1.0 - rate), -1).real)


def _unexplained(out: Diagnosis, monitor, e: np.ndarray, post: np.ndarray) -> bool:
    """Sets ``out.residual_ratio``, the :func:`noise_ratio` of the residual ``post`` the
    hypothesis leaves of ``e``; where it exceeds :func:`allowed_ratio` of ``e`` (the residual
    isolated is the baseline), the change is not the hypothesis (True, and ``out`` says so: no
    thruster, effect or size; the caller states no confidence, :func:`_none_named`), else
    ``out.isolated``."""
    out.residual_ratio = noise_ratio(monitor, post)
    if out.residual_ratio <= allowed_ratio(noise_ratio(monitor, e)):
        out.isolated = True
        return False
    out.kind, out.isolated, out.components = "model_change", False, None
    out.thruster = out.efficiency = out.efficiency_interval = None
    out.effect = out.value = out.stderr = out.p_value = None
    out.meaning = (
        f"{UNEXPLAINED}: the best, {out.hypothesis}, explains {100 * out.explained:.0f} % of "
        f"the residual and leaves {out.residual_ratio:.2g} times the healthy noise power"
    )
    return True


def profile_logl(drss: float, rss: float, n_eff: float) -> float:
    """The log-likelihood ratio of a fit that takes ``drss`` of the weighted residual sum of
    squares ``rss`` against none, over ``n_eff`` independent samples, the noise variance
    profiled out: n_eff/2 · ln(RSS₀/RSS₁). drss/2τ took the weighted noise's variance to be 1,
    the healthy one's, where the model's error grows with the fault (a residual 10⁵ times the
    noise read thousands of log-units between two hypotheses the data barely tell apart)."""
    if rss <= 0:
        return 0.0
    return 0.5 * n_eff * float(np.log(rss / max(rss - drss, np.finfo(float).eps * rss)))


def adjusted(p_value: float, tried: int) -> float:
    """The p-value ``p_value`` of the best of ``tried`` hypotheses, Bonferroni-adjusted over
    them (at most 1): what :data:`SIGNIFICANCE` is read against."""
    return float(min(1.0, p_value * max(tried, 1)))


def _ranked(names: list[str], posts: np.ndarray, null: float, skip: str | None = None) -> list:
    """The five likeliest of the hypotheses ``names`` (but ``skip``) and of no change
    (:data:`NO_CHANGE`, posterior ``null``), each with its posterior, likeliest first."""
    out = [{"hypothesis": n, "posterior": float(q)} for n, q in zip(names, posts, strict=True)]
    out = [a for a in out if a["hypothesis"] != skip]
    out.append({"hypothesis": NO_CHANGE, "posterior": null})
    return sorted(out, key=lambda a: -a["posterior"])[:5]


def _none_named(out: Diagnosis, posterior: float) -> None:
    """A diagnosis that names no hypothesis (none significant, or the best leaves more than
    :func:`allowed_ratio`): no confidence (None, not measured: it read the best rejected
    hypothesis' posterior among hypotheses none of which was found to be the change, "0.77"
    of one not significant, or 0 where that was 1.00); the posterior of the hypothesis it
    fitted (``out.hypothesis``: the one the fit chose, by priority among those the data cannot
    tell apart, not always the highest posterior) is said first among the alternatives."""
    out.confidence = None
    out.alternatives = [{"hypothesis": out.hypothesis, "posterior": posterior},
                        *out.alternatives][:5]  # fmt: skip


def _kind(s) -> str:
    if s.candidate.kind == "thruster_loss":
        return "thruster_loss"
    return "external_force" if s.candidate.kind == "external_bias" else "model_change"
