"""Weiss's decoupled identification sequence (Weiss eqs 99-108, section V.A).

Each step fits a few parameters from one DOF's equation on the runs that excite that DOF
alone (surge, sway, heave, roll, yaw), then plugs the estimates back in; pitch, which the
vehicle cannot drive, comes last from the coupled surge-heave run (eqs 105-108), fitted
together with surge and heave on their runs: the Munk moment (Z_ẇ − X_u̇) u w drives pitch
there, so their errors would otherwise land in M_q̇. A later step may refit a parameter. Fitting each
equation on its own run keeps the errors of one DOF out of the others (a coupled fit lets the
gyroscopic terms of C_A carry roll and pitch errors into yaw).

The covariance is block-diagonal over the steps: it does not carry the uncertainty of the
plugged-in values forward (they are far better determined than the parameters they feed).
A value a step could not identify (NaN: not excited on its runs) is not plugged in: a later
step reads that parameter at the vehicle file's value, as it reads a parameter no step has fitted
yet, and a warning names it (plugged in, the NaN made every row of each equation reading it
undefined, and those rows were dropped, so the later step's own unknowns read "not excited").
A refit that cannot identify a value an earlier step did keeps the earlier estimate (and its
verdict), plugged in as before, and a warning names both steps.
A parameter left NaN at the end (no step's runs identify it) stays NaN with a warning, as in
plain least squares, and the other steps' estimates stand; one that only steps whose equations
do not contain it fit (zero at any state, not only on their runs) is a mistake of the sequence,
an error.
The excitation report joins the steps' (:func:`~nnid.evaluation.persistence.combined_excitation`):
each parameter with the verdict of the step whose value it keeps.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from nnid.errors import ExcitationWarning, NnidInputError
from nnid.evaluation.persistence import ExcitationReport, combined_excitation
from nnid.physics.parts import at_file_value
from nnid.trainers.history import Progress, silent
from nnid.trainers.least_squares import Estimate, LeastSquares


@dataclass
class Step:
    experiments: Sequence[str]
    dofs: Sequence[str]
    unknowns: Sequence[str]


WEISS_STEPS = (
    Step(["surge"], ["u"], ["X_udot", "X:u*abs(u)"]),
    Step(["sway"], ["v"], ["Y_vdot", "Y:v*abs(v)"]),
    Step(["heave"], ["w"], ["Z_wdot", "Z:w*abs(w)"]),
    Step(["roll"], ["p"], ["K_pdot", "K:p*abs(p)"]),
    Step(["yaw"], ["r"], ["N_rdot", "N:r*abs(r)"]),
    Step(
        ["surge", "heave", "surge-heave"],
        ["u", "w", "q"],
        ["X_udot", "X:u*abs(u)", "Z_wdot", "Z:w*abs(w)", "M_qdot", "M:q*abs(q)"],
    ),
)
"""The sequence for Weiss's quadratic model (eqs 99-108) on the runs of
:class:`nnid.datasets.excitation.WeissSequence`."""


def _subset(data: dict[str, np.ndarray], names: Sequence[str]) -> dict[str, np.ndarray]:
    known = list(data["experiment_names"])
    # a step names a run: the pieces a gap cut it into (experiment_runs) are all its rows
    runs = list(data.get("experiment_runs", known))
    missing = [n for n in names if n not in known and n not in runs]
    if missing:
        raise NnidInputError(
            f"the log has no experiments {missing} (it has {known})", field="sequence"
        )
    wanted = set(names)
    codes = [
        c for c, (e, r) in enumerate(zip(known, runs, strict=True)) if e in wanted or r in wanted
    ]
    rows = np.isin(data["experiment"], codes)
    return {
        k: (v[rows] if isinstance(v, np.ndarray) and v.shape[:1] == rows.shape else v)
        for k, v in data.items()
    }


def step_label(k: int, step: Step) -> str:
    """How the warnings name the sequence's step ``k`` (from 0): "step 2 (v, r)"."""
    return f"step {k + 1} ({', '.join(step.dofs)})"


def step_equations(
    structure, name: str, step: Step, data: dict[str, np.ndarray], filter_lambda: float | None
) -> list[str]:
    """The DOFs of ``step`` whose equations read parameter ``name`` on its runs ``data``: its
    regression column (``structure.restricted([name], ...)``, Weiss eqs 99-108) is not all
    zero in their rows there (NaN counts: an undefined entry still reads it)."""
    reg = structure.restricted([name], step.dofs, {}).regression(data, filter_lambda)
    rows = reg.phi[:, 0].reshape(-1, len(step.dofs))  # sample-major, one row per equation
    return [d for d, read in zip(step.dofs, np.any(rows != 0, axis=0), strict=True) if read]


def step_reads(
    structure, name: str, step: Step, data: dict[str, np.ndarray], filter_lambda: float | None
) -> bool:
    """Whether the equations of ``step`` read parameter ``name`` on its runs ``data``
    (:func:`step_equations`), so that the value the step takes for it enters its estimates."""
    return bool(step_equations(structure, name, step, data, filter_lambda))


#: a generic state of the vehicle for :func:`step_contains`, fixed (no generator): two
#: samples with every velocity, acceleration, pose component and force nonzero, of both
#: signs (an installation coefficient of negative thrust reads only a negative force)
_PROBE_NU = np.array(
    [[0.31, -0.23, 0.17, 0.13, -0.11, 0.29], [-0.27, 0.19, -0.21, -0.15, 0.12, -0.18]]
)
_PROBE_NU_DOT = np.array(
    [[0.07, 0.05, -0.09, 0.04, 0.06, -0.03], [-0.08, -0.06, 0.05, -0.07, -0.04, 0.09]]
)
_PROBE_ETA = np.array([[1.3, -0.7, 2.1, 0.21, -0.17, 0.43], [-0.9, 1.1, 1.7, -0.19, 0.23, -0.37]])
_PROBE_TAU = np.array([[13.0, 7.0, 11.0, 3.0, 2.0, 5.0], [-9.0, -8.0, -12.0, -4.0, -3.0, -6.0]])


def step_contains(structure, name: str, step: Step) -> bool:
    """Whether the equations of ``step`` contain parameter ``name`` at all: its regression
    column (Weiss eqs 99-108) is not zero at a generic state (:data:`_PROBE_NU` and the
    others), whatever the step's runs. A column that is zero only on the runs (they never move
    what it multiplies: N:v in a yaw run where v ≡ 0) is a data outcome, not this."""
    probe = {
        "t": np.arange(len(_PROBE_NU), dtype=float),
        "experiment": np.zeros(len(_PROBE_NU), dtype=int),
        "nu": _PROBE_NU.copy(),
        "nu_dot": _PROBE_NU_DOT.copy(),
        "eta": _PROBE_ETA.copy(),
        "tau": _PROBE_TAU.copy(),
    }
    return bool(step_equations(structure, name, step, probe, None))


def resting_on(
    structure,
    name: str,
    step: Step,
    data: dict[str, np.ndarray],
    filter_lambda: float | None,
    unknowns: Sequence[str],
) -> list[str]:
    """The ``unknowns`` of ``step`` whose estimates rest on the value it takes for ``name``:
    those its equations read where they read ``name`` (:func:`step_equations`; that value's
    error is in their targets), and those sharing an equation with one of them (least squares
    solves them together, so the error reaches them through it). [] where no equation reads
    ``name``."""
    reached = set(step_equations(structure, name, step, data, filter_lambda))
    reads = {n: set(step_equations(structure, n, step, data, filter_lambda)) for n in unknowns}
    out: set[str] = set()
    grew = bool(reached)
    while grew:  # the equations the error reaches, through the unknowns that join them
        joined = {n for n, eqs in reads.items() if eqs & reached} - out
        out |= joined
        grew = bool(joined)
        for n in joined:
            reached |= reads[n]
    return [n for n in unknowns if n in out]


def sequence_steps(sequence: str | Sequence[Step | Mapping]) -> list[Step]:
    """The steps of a sequence: ``"weiss"`` (:data:`WEISS_STEPS`) or a list of steps, each a
    :class:`Step` or a mapping with its fields."""
    if isinstance(sequence, str):
        if sequence != "weiss":
            raise NnidInputError(
                f"sequence '{sequence}': expected 'weiss' or a list of steps", field="sequence"
            )
        return list(WEISS_STEPS)
    return [s if isinstance(s, Step) else Step(**s) for s in sequence]


def sequence_dofs(steps: Sequence[Step]) -> list[str]:
    """The DOFs whose equations a sequence's steps fit, in order, each once."""
    return list(dict.fromkeys(d for s in steps for d in s.dofs))


class DecoupledSequence:
    """Trainer: run the steps in order with ``trainer`` (least squares by default). The
    structure it fits must offer ``restricted(unknowns, dofs, known)``: the structure of one
    step with the earlier steps' estimates plugged in."""

    def __init__(self, steps: Sequence[Step] = WEISS_STEPS, trainer=None) -> None:
        self.steps = list(steps)
        self.trainer = trainer or LeastSquares()
        self.filter_lambda = getattr(self.trainer, "filter_lambda", None)

    @property
    def kind(self) -> str:
        return f"{getattr(self.trainer, 'kind', type(self.trainer).__name__)} (decoupled sequence)"

    def fit(
        self, structure, data: dict[str, np.ndarray], progress: Progress | None = None
    ) -> Estimate:
        names = list(structure.names)
        theta = np.full(len(names), np.nan)
        cov = np.full((len(names), len(names)), np.nan)
        found: dict[str, float] = {}  # identified values, plugged into the later steps
        lost: dict[str, int] = {}  # a parameter the latest step fitting it left NaN: that step
        prior: dict[tuple[str, int], list[int]] = {}  # (it, that step): steps reading its prior
        source: dict[str, int] = {}  # the step whose estimate a parameter holds
        refits: dict[tuple[str, int], list[int]] = {}  # (it, that step): refits that left NaN
        self.unidentified_: list[list[str]] = []  # per step: left NaN, and no earlier value
        self.kept_: list[list[str]] = []  # per step: left NaN, an earlier step's estimate kept
        tried: dict[str, list[tuple[int, bool]]] = {}  # left NaN: (step, its equations have it)
        n_obs = 0
        checks: list[tuple[list[str], ExcitationReport | None]] = []
        report = progress or silent
        for k, step in enumerate(self.steps):
            try:
                sub = structure.restricted(step.unknowns, step.dofs, found)
                subset = _subset(data, step.experiments)
            except NnidInputError as exc:  # the step's own field, not the model's
                raise NnidInputError(f"step {k + 1}: {exc.message}", field="sequence") from None
            est = self.trainer.fit(sub, subset)
            report(k + 1, len(self.steps), f"sequence step {k + 1}: {', '.join(step.dofs)}")
            for name, j in lost.items():
                if name not in sub.names and step_reads(
                    structure, name, step, subset, self.filter_lambda
                ):
                    prior.setdefault((name, j), []).append(k)
            # NaN is no value: plugged in, it undefined every row of each equation reading it
            missing = [n for n, v in zip(sub.names, est.theta, strict=True) if not np.isfinite(v)]
            # an earlier step's estimate outlives a refit that could not identify it: the
            # refit measured nothing, and dropping the estimate left the parameter unidentified
            kept = [n for n in missing if n in found]
            given = [n for n in sub.names if n not in kept]
            idx = [names.index(n) for n in given]
            pos = [list(sub.names).index(n) for n in given]
            theta[idx] = est.theta[pos]
            # block-diagonal over the steps: a refitted value's covariance with the values an
            # earlier step left (kept, or not refitted) is not measured
            cov[idx, :] = np.nan
            cov[:, idx] = np.nan
            cov[np.ix_(idx, idx)] = est.cov[np.ix_(pos, pos)]
            for name, value in zip(sub.names, est.theta, strict=True):
                if name in kept:
                    refits.setdefault((name, source[name]), []).append(k)
                elif name in missing:
                    found.pop(name, None)
                    lost[name] = k
                else:
                    found[name] = float(value)
                    source[name] = k
                    lost.pop(name, None)
            for name in missing:  # structural, not on these runs: they may not move its factor
                tried.setdefault(name, []).append((k, step_contains(structure, name, step)))
            self.unidentified_.append([n for n in missing if n not in kept])
            self.kept_.append(kept)
            n_obs += est.n_obs
            checks.append((given, est.excitation))  # a kept one keeps its verdict too
        if prior:
            vehicle = structure.restricted([], self.steps[0].dofs, {}).base  # nothing set
            # the value it reads: the declared one, or 0 where the file has no such term
            said = [
                f"{step_label(j, self.steps[j])} could not identify {name}, so "
                + ", ".join(step_label(i, self.steps[i]) for i in steps)
                + f" read it {at_file_value(vehicle.declared(name))}"
                for (name, j), steps in prior.items()
            ]
            warnings.warn(
                "later sequence steps read a parameter that an earlier step left unidentified "
                "at the vehicle file's value, not at an estimate; their estimates rest on that "
                "prior, and their standard errors do not include its error: " + "; ".join(said),
                ExcitationWarning,
                stacklevel=2,
            )
        if refits:
            said = [
                f"{name} from {step_label(j, self.steps[j])}, which "
                + ", ".join(step_label(i, self.steps[i]) for i in steps)
                + " refitted and could not identify"
                for (name, j), steps in refits.items()
            ]
            warnings.warn(
                "a later sequence step refitted a parameter on runs that do not identify it: "
                "the earlier step's estimate is kept, and plugged into the steps after: "
                + "; ".join(said),
                ExcitationWarning,
                stacklevel=2,
            )
        left = [n for n, v in zip(names, theta, strict=True) if not np.isfinite(v)]
        self._check_left(left, tried)
        # the steps' unexcited and collinear verdicts, which the reports show beside each
        # parameter: the combined estimate had none, so its "not significant" read as a test
        return Estimate(names, theta, cov, float("nan"), n_obs, combined_excitation(checks, names))

    def _check_left(self, left: list[str], tried: Mapping[str, list[tuple[int, bool]]]) -> None:
        """Judge the parameters ``left`` NaN after the whole sequence (``tried``: per parameter,
        each step that fitted it and left it NaN, with whether its equations contain it,
        :func:`step_contains`). One that no step fits, or that only steps whose equations do
        not contain it fit (N_rdot in a surge step), is a mistake of the sequence, whatever
        the data: NnidInputError. One a step's equations contain was not identified by its
        runs (not excited, a factor its runs never move, or read only by rows left out): a data
        outcome, so it stays NaN with a warning, as plain least squares leaves it, and the
        parameters the other steps identified stand."""
        unread = [n for n in left if not any(has for _, has in tried.get(n, []))]
        if unread:
            said = [
                f"{n}: "
                + (
                    "the equations of "
                    + ", ".join(step_label(k, self.steps[k]) for k, _ in tried[n])
                    + ", which fit it, do not contain it (its regressor is zero whatever the "
                    "motion)"
                    if n in tried
                    else "no step has it among its unknowns"
                )
                for n in unread
            ]
            raise NnidInputError(
                f"no step of the sequence identifies {unread}: "
                + "; ".join(said)
                + "; fit each in a step whose equations contain it",
                field="sequence",
            )
        if left:
            said = [
                f"{n} (tried by "
                + ", ".join(step_label(k, self.steps[k]) for k, _ in tried[n])
                + ")"
                for n in left
            ]
            warnings.warn(
                "the sequence left parameters unidentified: the runs of the steps that fit them "
                "do not identify them (see each step's excitation verdict); they are NaN in the "
                "estimate, without a standard error, and the other steps' estimates stand: "
                + ", ".join(said),
                ExcitationWarning,
                stacklevel=3,
            )
