"""The residual loop as an estimator: baseline, diagnose, augment, refit, before and after.

``ResidualLoop(vehicle).fit(log)`` splits the log (whole experiments held out when there are
three or more, else the last block of each), derives velocities and accelerations where they
are missing (Savitzky-Golay), fits the baseline (the vehicle file with its damping structure
re-identified), then repeats: rank every candidate effect by how much of the held-out residual
it explains when added and refitted (:mod:`nnid.loop.diagnose`), add the best admissible one,
refit; until none is significant or ``max_effects`` are in. Errors before and after are
measured on the held-out part only: free-run and one-step velocity NRMSE per DOF, and the
force residual RMS per DOF (McCarter eq. 4.4 minus the model's damping). The loop has no
test part: the held-out part that measures "after" also ranked the candidates and gated the
one added, so "after" is not an independent test of it (``validation_used_for``).
"""

from __future__ import annotations

import copy
import time
import warnings

import numpy as np
import pandas as pd

from nnid.datasets.arrays import logged_inputs, nominal_forces
from nnid.datasets.gaps import mask_gaps
from nnid.datasets.log import ANGLES, check_log, frame_step, log_step, run_pieces
from nnid.datasets.preprocess import experiment_rows, refuse_bursty_runs
from nnid.datasets.splits import say_missed_fractions, split_log
from nnid.errors import NnidInputError
from nnid.evaluation.evaluate import MODE_KEYS, diverged_key
from nnid.loop.diagnose import (
    Fit,
    Scored,
    Step,
    Workspace,
    force_residual,
    force_rmse,
    predict,
    refit,
    rescore,
    residual_correlation_time,
    reweight,
    run_stderr,
    screen_linear,
    search_nonlinear,
    sindy_opinion,
    velocity_scores,
)
from nnid.loop.effects import candidates
from nnid.loop.residuals import correlation_analysis
from nnid.loop.unexplained import as_records, describe, unexplained_structure
from nnid.models.base import FIT_AND_SIMULATION
from nnid.models.parametric import EQUATION_COLUMNS, vehicle_with
from nnid.physics.dofs import DOF_WORD, DOFS, FORCES
from nnid.physics.parts import Parts
from nnid.reports.cells import score
from nnid.threads import blas_threads, torch_threads
from nnid.trainers.history import Progress, silent
from nnid.trainers.least_squares import significant
from nnid.warning_messages import warning_messages

#: the gate's horizon where the free run diverges, and the k-step error reported (seconds)
FALLBACK_S = 1.0
#: independent held-out samples (scored samples over the residual's correlation time) below
#: which the loop's before/after is said to be a rough reading
MIN_INDEPENDENT = 10
#: an effect whose one-step held-out error is this many times the fit's is never added
MAX_WORSENING = 10.0
#: how much worse (relative) the reported model's held-out simulation error may be than the
#: one the gate accepted the last effect on before it is said (``after_vs_gate``): the reweighted
#: refit is a new model, but on a log that determines it the two agree to rounding (the demo's
#: 0.0230932088905198 against ...5197, 5e-15 apart); 1e-6 is far above that rounding and below
#: any change in the digits a report prints
AFTER_GATE_RTOL = 1e-6


def gate_verdicts(step: Step) -> dict[str, list]:
    """A pass's candidates that passed every test but the simulation gate, by what the gate
    did (loop.json's keys): turned down for no gain in simulation; refused there for another
    reason (its one-step error grew, its refit not physical), each with it; not simulated,
    beyond ``gate_checks`` (:data:`NOT_GATED`)."""
    return {
        "gate_turned_down": [s.name for s in step.ranked if NO_GAIN in s.reason],
        "gate_refused": [
            {"effect": s.name, "reason": s.reason}
            for s in step.ranked
            if s.reason.startswith((ONE_STEP_GROWS, NOT_PHYSICAL))
        ],
        "not_gated": [s.name for s in step.ranked if s.reason.startswith(NOT_GATED)],
    }


def _scored(step: Step) -> list[Scored]:
    """The candidates of a pass that were scored (excited, identifiable beside the model and
    finite on its rows), best first: the others measure nothing."""
    return [s for s in step.ranked if s.scored]


class ResidualLoop:
    """Find effects the vehicle file lacks in a log, add them, and report before and after.

    Parameters: ``alpha`` family-wise significance of the F-test (Bonferroni over the
    candidates tested), ``min_improvement`` the fraction of held-out residual a candidate must
    remove in the DOF it explains most, ``max_effects`` how many effects at most,
    ``validation`` the held-out fraction, ``coupled`` whether coupled damping terms of the
    basis library are candidates, ``warmup_s`` excluded from every free-run score,
    ``min_gate_gain`` the fraction by which a candidate must lower the held-out simulation
    error (free run, or ``gate_horizon_s`` ahead) of the ``gate_checks`` best ranked, ``dofs``
    the DOF equations analysed (default: those with a velocity in the log),
    ``validation_experiments`` the held-out runs by name, ``second_opinion`` a fitted
    :class:`nnid.models.hybrid.HybridModel` of this vehicle whose learned force, named in the
    effect vocabulary on the training part (:func:`nnid.loop.explain.explain`), is reported
    beside the loop's own diagnosis. ``max_bridge_s``: velocity gaps up to this long are
    bridged from the pose where it allows; the others are masked (:mod:`nnid.datasets.gaps`).
    """

    def __init__(
        self,
        vehicle,
        alpha: float = 0.01,
        min_improvement: float = 0.005,
        max_effects: int = 3,
        validation: float = 0.3,
        coupled: bool = True,
        nonlinear: bool = True,
        savgol_window: float = 1.0,
        savgol_order: int = 4,
        warmup_s: float = 2.0,
        min_gate_gain: float = 0.05,
        filter_lambda: float | None = 1.0,
        zoh_midpoint: bool = True,
        gate_checks: int = 10,
        report_candidates: int = 100,
        dofs: tuple[str, ...] | None = None,
        validation_experiments: list[str] | None = None,
        rescore_top: int = 30,
        gate_horizon_s: float | None = None,
        second_opinion=None,
        max_bridge_s: float = 2.0,
    ) -> None:
        self.vehicle = vehicle
        self.alpha = alpha
        self.min_improvement = min_improvement
        self.max_effects = max_effects
        self.validation = validation
        self.coupled = coupled
        self.nonlinear = nonlinear
        self.savgol_window = savgol_window
        self.savgol_order = savgol_order
        self.warmup_s = warmup_s
        self.min_gate_gain = min_gate_gain
        self.filter_lambda = filter_lambda
        self.zoh_midpoint = zoh_midpoint
        self.gate_checks = gate_checks
        self.report_candidates = report_candidates
        self.dofs = dofs
        self.validation_experiments = validation_experiments
        self.rescore_top = rescore_top
        self.gate_horizon_s = gate_horizon_s
        self.second_opinion = second_opinion
        self.max_bridge_s = max_bridge_s

    # -- data -----------------------------------------------------------------------------------
    def _prepare(self, log: pd.DataFrame) -> pd.DataFrame:
        from nnid.datasets.cleaning import CleaningReport
        from nnid.datasets.gaps import bridge_from_pose, fill_slow, find_gaps, gaps_record
        from nnid.datasets.preprocess import derive_accelerations, derive_velocities

        self.cleaning_ = CleaningReport(source="loop data")
        # an attitude logged slower than the clock is filled from the gyro between its samples
        # (restoring forces need it on every row); what is left empty is a gap
        log = fill_slow(log, self.cleaning_)
        self.gaps_ = gaps_record(find_gaps(log))
        derived = any(d not in log for d in DOFS) and all(a in log for a in ANGLES)
        if derived:
            log = derive_velocities(log, self.savgol_window, self.savgol_order, self.cleaning_)
        log = bridge_from_pose(
            log, self.savgol_window, self.savgol_order, self.max_bridge_s, self.cleaning_
        )
        if any("d" + d not in log for d in DOFS):
            # derive_velocities has warned of the log's uneven runs (bridging keeps its clock)
            log = derive_accelerations(
                log, self.savgol_window, self.savgol_order, self.cleaning_, warn_uneven=not derived
            )
        return log

    def _split(self, log: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
        frac = (1.0 - self.validation, self.validation, 0.0)
        if self.validation_experiments:
            names = list(dict.fromkeys(log["experiment"])) if "experiment" in log else []
            held = run_pieces(log, self.validation_experiments)  # a run cut at gaps: its pieces
            unknown = [n for n in held if n not in names]
            if unknown:
                raise NnidInputError(
                    f"validation experiments not in the log: {', '.join(map(str, unknown))}",
                    field="validation",
                )
            assignment = {
                "train": [n for n in names if n not in held],
                "validation": list(held),
                "test": [],
            }
            if not assignment["train"]:
                raise NnidInputError(
                    "every experiment is held out: nothing is left to fit on", field="validation"
                )
            split = split_log(log, "experiment", frac, assignment)
            self.split_ = split.record
            return split.train, split.validation
        n_exp = log["experiment"].nunique() if "experiment" in log else 1
        split = split_log(log, "experiment" if n_exp >= 3 else "block", frac)
        if len(split.validation) == 0 or len(split.train) == 0:
            split = split_log(log, "block", frac)
        say_missed_fractions(split)
        self.split_ = split.record
        return split.train, split.validation

    # -- the loop -------------------------------------------------------------------------------
    def fit(self, log: pd.DataFrame, progress: Progress | None = None) -> ResidualLoop:
        """Run the loop on ``log``; ``progress(pass, passes, message)`` is called as each pass
        starts. Warnings raised on the way (unexcited parameters, ...) are kept in
        ``warnings_``."""
        start = time.perf_counter()
        log = check_log(log)
        # its fits and simulations step at a run's typical step, one inside a burst: the
        # pipeline refuses such a log before the loop, a caller in Python here
        refuse_bursty_runs(log, FIT_AND_SIMULATION)
        report = progress or silent
        total = self.max_effects + 1

        def say(message: str, done: int = 0) -> None:
            report(done, total, message)

        # one thread per library: pinned numbers are one BLAS thread's (nnid.threads says why)
        with (
            torch_threads(1),
            blas_threads(1),
            warnings.catch_warnings(record=True) as caught,
        ):
            warnings.simplefilter("always")
            self._fit(log, say)
        self.warnings_ = warning_messages(caught)
        self.seconds_ = time.perf_counter() - start
        return self

    def _fit(self, log: pd.DataFrame, say) -> None:
        say("fitting the baseline")
        logged_inputs(log, self.vehicle)  # a clear error before any work
        log = self._prepare(log)
        train, val = self._split(log)
        # split first, on whole runs as if complete, so that gaps never move the split
        needed = [c for c in EQUATION_COLUMNS if c in log]  # what the Fossen regression reads
        train, val = mask_gaps([train, val], needed, self.cleaning_, ("training", "held-out"))
        self.dofs_ = tuple(self.dofs) if self.dofs else tuple(d for d in DOFS if d in log)
        if not self.dofs_:
            raise NnidInputError(
                "the log has no body velocity u v w p q r, and no pose to derive one"
            )
        ws = Workspace(train, val, self.vehicle, self.filter_lambda, self.zoh_midpoint, self.dofs_)
        used = {FORCES[DOFS.index(d)] for d in self.dofs_}
        unknowns = [k for k in Parts.from_vehicle(self.vehicle).damping if k.split(":")[0] in used]
        self._check_lengths(train, val, len(unknowns))
        fit = refit(ws, self.vehicle, unknowns)
        ws.tau_corr = residual_correlation_time(fit.e, self.dofs_)
        _warn_unphysical_damping(fit, float(np.sqrt(ws.tau_corr)))
        self._say_short_held_out(val, ws.tau_corr)
        self.baseline_ = fit
        self.steps_: list[Step] = []
        self.gates_: list[str | None] = []  # the simulation each pass's gate compared
        added: list[Scored] = []
        pool = [
            c
            for c in candidates(self.vehicle, train, self.coupled)
            if set(c.dofs) & set(self.dofs_)
        ]
        while len(added) < self.max_effects:
            say(f"pass {len(added) + 1}: testing {len(pool)} candidate effects", len(added))
            step = self._step(ws, fit, pool)
            self.steps_.append(step)
            if step.added is None:
                break
            added.append(step.added)
            fit = reweight(ws, step.fit)  # the next pass weighs by the model it now has
            pool = [c for c in pool if c.name != step.added.candidate.name]
        self.fit_ = fit
        self.added_ = added
        # what an added effect's final s.e. is read from (:meth:`_final_effect`), once
        self.final_widen_ = float(np.sqrt(residual_correlation_time(fit.e, self.dofs_)))
        self.run_stderr_ = run_stderr(ws, fit)
        self.before_, self.residuals_before_ = self._scores(ws, self.baseline_)
        if fit is self.baseline_:  # nothing added: the final model is the baseline just scored
            self.after_, self.residuals_after_ = copy.deepcopy(
                (self.before_, self.residuals_before_)
            )
        else:
            self.after_, self.residuals_after_ = self._scores(ws, fit)
        # after the scores: the free run the gate compares is then the one "after" reports
        self.after_vs_gate_ = self._after_vs_gate(ws, fit, added)
        self.workspace_ = ws
        self.unexplained_ = self._unexplained(ws, fit)
        self.hybrid_opinion_ = None
        if self.second_opinion is not None:
            from nnid.loop.explain import explain

            say("asking the hybrid what its network learned", len(added))
            self.hybrid_opinion_ = explain(self.second_opinion, train).as_dict()

    def _after_vs_gate(self, ws: Workspace, fit: Fit, added: list[Scored]) -> dict | None:
        """The reported model's held-out simulation error beside the one the gate accepted the
        last effect on, in that pass's gate mode; warned where the reported one is worse by
        more than :data:`AFTER_GATE_RTOL` or diverges. The gate simulated the candidate's own
        refit; "after" is the joint refit reweighted, which no gate checked. None where
        nothing was added. Never changes what was added or the scores reported."""
        if not added:
            return None
        s = added[-1]
        what = self.gates_[len(added) - 1]  # the pass that added it gated in a mode (not None)
        gated = s.gate[1] if s.gate is not None else None  # finite: the gate accepted on it
        reported = self._simulation_error(ws, fit.vehicle, dict(self._gate_modes(ws))[what])
        worse = reported is None or (gated is not None and reported > gated * (1 + AFTER_GATE_RTOL))
        if worse:
            how = (
                f"diverges in the held-out {what}, where the model the gate accepted it on "
                f"scored {gated:.6g}"
                if reported is None
                else f"scores {reported:.6g} in the held-out {what}, "
                f"{100 * (reported / gated - 1):.2g} % worse than the {gated:.6g} of the model "
                "the gate accepted it on"
            )
            warnings.warn(
                f"the reported model (the joint refit, reweighted, once {s.name} was added) "
                f"{how}: the simulation gate did not check the model reported as 'after' "
                "(after_vs_gate in loop.json)",
                stacklevel=2,
            )
        return {"gate": what, "gated": gated, "reported": reported, "worse": bool(worse)}

    def _check_lengths(self, train: pd.DataFrame, val: pd.DataFrame, unknowns: int) -> None:
        """A log too short for what is asked of it is refused, naming the setting: no held-out
        run longer than the warm-up and one scored second, or fewer training rows than ten per
        coefficient to fit."""
        durations = [
            float(part["t"].iloc[-1] - part["t"].iloc[0])
            for _, part in val.groupby("experiment", sort=False)
        ] if "experiment" in val else [float(val["t"].iloc[-1] - val["t"].iloc[0])]  # fmt: skip
        # the held-out share is the 'validation' argument here, but 'validation_fraction' in a
        # loop config, where 'validation' (and --validation) names the held-out runs
        named = bool(self.validation_experiments)
        if max(durations, default=0.0) <= self.warmup_s + FALLBACK_S:
            raise NnidInputError(
                f"the longest held-out run is {max(durations, default=0.0):.3g} s: no longer "
                f"than the warm-up ({self.warmup_s:g} s) plus {FALLBACK_S:g} s to score; give a "
                "longer log or more experiments, "
                + (
                    "hold out longer runs (validation)"
                    if named
                    else f"hold out more than {self.validation:g} (validation_fraction)"
                )
                + ", or a shorter warmup_s",
                field="warmup_s",
            )
        if len(train) * len(self.dofs_) < 10 * max(unknowns, 1):
            raise NnidInputError(
                f"{len(train)} training samples for {unknowns} damping coefficients in "
                f"{len(self.dofs_)} DOFs: fewer than ten equations per coefficient; give a "
                "longer log or hold out "
                + (
                    "fewer runs (validation)"
                    if named
                    else f"less than {self.validation:g} (validation_fraction)"
                ),
                field="validation" if named else "validation_fraction",
            )
        if np.isnan(frame_step(train)):
            # every later step reads a step of the training runs (the filter's settling, the
            # actuator lag's bound): none has one, and "actuator_lag = nan leaves no valid
            # vehicle" or a division by zero blamed the vehicle or the filter
            raise NnidInputError(
                f"no training run has two samples ({len(train)} rows, each a run of its own): "
                "the loop fits accelerations over runs of samples; give longer runs",
                field="experiment",
            )

    def _say_short_held_out(self, val: pd.DataFrame, tau_corr: float) -> None:
        """Warn when the held-out scores rest on fewer than :data:`MIN_INDEPENDENT`
        independent samples: the scored samples (after each run's warm-up) over the residual's
        correlation time. A before/after on a 13-sample run ("fell from 0.749 to 0.182") is a
        reading of a few seconds, not a measured improvement of the model."""
        scored = 0
        t_all = val["t"].to_numpy(np.float64)
        for _, pos in experiment_rows(val):
            t = t_all[pos]
            scored += int(np.sum(t - t[0] >= self.warmup_s))
        independent = scored / max(tau_corr, 1.0)
        if independent < MIN_INDEPENDENT:
            warnings.warn(
                f"the held-out scores rest on {scored} samples after the warm-up, about "
                f"{independent:.0f} independent ones at the residual's correlation time of "
                f"{tau_corr:.0f} samples: the error before and after is a rough reading; hold "
                "out a longer run (validation)",
                stacklevel=2,
            )

    def _step(self, ws: Workspace, fit: Fit, pool) -> Step:
        known = set(fit.unknowns)
        linear = [c for c in pool if c.linear and c.parameter not in known]
        scored = screen_linear(ws, fit, linear)
        # searches that ran and found no better fit: tested, with nothing to rank, named so
        # that a reader sees what the count holds (a candidate whose linearised column
        # measures nothing comes back named, not searched)
        found_nothing: list[str] = []
        if self.nonlinear:
            for cand in pool:
                if not cand.linear:
                    s = search_nonlinear(ws, fit, cand)
                    if s is not None:
                        scored.append(s)
                    else:
                        found_nothing.append(cand.name)
        # Bonferroni over the candidates tested: a candidate not excited, not identifiable
        # beside the model or not finite on its rows had no test (no p-value), and counting
        # them (165 of BlueROV1's 324) made the threshold stricter than the family tested asks
        tested = max(sum(s.scored for s in scored) + len(found_nothing), 1)
        # a candidate not scored (not excited, not identifiable, not finite) measures nothing:
        # ranked after every other
        scored.sort(key=lambda s: (not s.scored, -s.improvement if s.scored else 0.0))
        rescore(ws, fit, scored[: self.rescore_top])
        for s in scored:
            if s.scored:  # the others keep their verdict (NOT_EXCITED, ..., NOT_FINITE)
                self._judge(s, tested, fit)
        try:
            sindy = sindy_opinion(ws, fit, scored)
        except Exception as exc:  # a second opinion must not stop the loop
            sindy = [f"(pysindy failed: {exc})"]
        chosen, augmented = self._simulation_gate(ws, fit, [s for s in scored if s.admissible])
        return Step(scored, chosen, sindy, augmented, tested, found_nothing)

    def _gate_modes(self, ws: Workspace) -> list[tuple[str, str | int]]:
        """The held-out simulations the gate may compare, first choice first: the free run (or
        ``gate_horizon_s`` ahead), then :data:`FALLBACK_S` ahead, then one step. The first one
        in which the current fit does not diverge is used, for the fit and every candidate
        alike: a diverged error is never compared with a finite one."""
        dt = frame_step(ws.val)  # its runs' step, the joins between them left out
        modes: list[tuple[str, str | int]] = []
        if self.gate_horizon_s is None:
            modes.append(("free run", "free_run"))
        else:
            modes.append(
                (f"{self.gate_horizon_s:g} s ahead", max(round(self.gate_horizon_s / dt), 1))
            )
        k = max(round(FALLBACK_S / dt), 1)
        if all(m != k for _, m in modes):
            modes.append((f"{FALLBACK_S:g} s ahead", k))
        return [*modes, ("one step", "one_step")]

    def _simulation_gate(
        self, ws: Workspace, fit: Fit, admissible: list[Scored]
    ) -> tuple[Scored | None, Fit | None]:
        """The best-ranked admissible candidate that also improves the held-out simulation
        (free run, or k steps ahead with ``gate_horizon_s``; where the fit's free run diverges,
        the first horizon at which it does not, for every candidate alike) and does not make
        the one-step error worse by more than :data:`MAX_WORSENING` times.

        A column built from measured accelerations or velocities carries their noise, and so
        does the residual: such a candidate "explains" held-out noise (errors in variables)
        while its simulation gets worse. The free run, driven by the inputs alone, cannot be
        fooled that way."""
        modes = self._gate_modes(ws)
        before, what, mode = None, "", "free_run"
        for label, m in modes:
            what, mode = label, m
            before = self._simulation_error(ws, fit.vehicle, mode)
            if before is not None:
                break
        self.gates_.append(what if before is not None else None)
        if before is None:
            for s in admissible:
                s.admissible = False
                s.reason = UNJUDGED
            return None, None
        one_step = None
        for s in admissible[: self.gate_checks]:
            try:
                vehicle = s.candidate.augment(vehicle_with(fit.vehicle, s.refit), s.value)
            except ValueError as exc:  # it stayed "admissible, ranked below the one added"
                s.admissible = False
                s.reason = f"{NOT_PHYSICAL}: {str(exc).splitlines()[0]}"
                continue
            after = self._simulation_error(ws, vehicle, mode)
            s.gate = (before, after)
            # the free run (or the set horizon) must gain min_gate_gain; a shorter fallback
            # horizon, dominated by noise, must only not get worse: the held-out force residual
            # has already judged the improvement
            gain = self.min_gate_gain if what == modes[0][0] else 0.0
            if after is not None and after < before * (1 - gain):
                if one_step is None:
                    one_step = self._simulation_error(ws, fit.vehicle, "one_step")
                worse = self._simulation_error(ws, vehicle, "one_step")
                if one_step is not None and (
                    worse is None or worse > MAX_WORSENING * max(one_step, 1e-12)
                ):
                    s.admissible = False
                    s.reason = (
                        f"{ONE_STEP_GROWS} from {score(one_step, fixed=True)} to "
                        f"{score(worse, fixed=True)}"
                    )
                    continue
                try:
                    augmented = self._augment(ws, fit, s)
                except ValueError as exc:  # the joint refit left the physical range
                    s.admissible = False
                    s.reason = f"{NOT_PHYSICAL}: {str(exc).splitlines()[0]}"
                    continue
                s.reason = "added" if what == "free run" else f"added (judged {what})"
                return s, augmented
            s.admissible = False
            s.reason = (
                f"held-out {what} {NO_GAIN} "
                f"({score(before, fixed=True)} -> {score(after, fixed=True)})"
            )
        # nothing was added: those never simulated are not "ranked below the one added"
        for s in admissible[self.gate_checks :]:
            s.admissible = False
            s.reason = f"{NOT_GATED} = {self.gate_checks})"
        return None, None

    def _simulation_error(self, ws: Workspace, vehicle, mode: str | int) -> float | None:
        """Held-out velocity NRMSE (mean over the analysed DOFs) of a simulation ``mode``;
        None where it diverges."""
        return self._velocity_scores(ws, vehicle, mode)[0]["total"]

    def _velocity_scores(
        self, ws: Workspace, vehicle, mode: str | int
    ) -> tuple[dict[str, float | None], dict[str, float]]:
        """:func:`~nnid.loop.diagnose.velocity_scores` of ``vehicle`` on the held-out part,
        simulated once per vehicle and mode in a fit: the gate's simulation of the current fit
        is the one its before (or after) scores report. Keyed by the vehicle object, which the
        loop never changes once made (:func:`vehicle_with` makes a new one), and held in the
        memo so that its id is not reused; copies, so that no caller's edit reaches another."""
        key = (id(vehicle), mode)
        if key not in ws.simulations:
            scores = velocity_scores(vehicle, ws.val, mode, self.warmup_s, self.dofs_)
            ws.simulations[key] = (vehicle, scores)
        scores, diverged = ws.simulations[key][1]
        return dict(scores), dict(diverged)

    def _judge(self, s: Scored, tested: int, fit: Fit) -> None:
        """Admissible: significant after Bonferroni, a significant parameter (Caccia), a
        held-out improvement, and a vehicle that stays physical."""
        best_dof = max(s.dof_improvement.values(), default=0.0)
        if s.candidate.kind == "restoring_offset":
            gain = s.dof_improvement
            dof = "p" if gain.get("p", -np.inf) >= gain.get("q", -np.inf) else "q"
            s.candidate = s.candidate.renamed(f"restoring_offset.{FORCES[DOFS.index(dof)]}")
        if not s.p_value < self.alpha / tested:
            s.reason = f"not significant (p = {s.p_value:.2g} ≥ {self.alpha / tested:.2g})"
        elif np.isnan(s.stderr):
            # no s.e. was measured (a 1-D search's column linearised at its value measured
            # nothing, or its range leaves no step): an uncertainty never read is no parameter
            # shown significant (Caccia's test). Its percentile error is NaN, or inf at 0
            why = f": {s.unmeasured};" if s.unmeasured else ":"
            s.reason = f"parameter uncertainty not measured{why} its significance cannot be shown"
        elif not significant(s.percentile_error):
            s.reason = f"parameter uncertain ({s.percentile_error:.0f} % > 51 %)"
        elif not (best_dof >= self.min_improvement and s.improvement > 0):
            s.reason = (
                f"held-out residual falls by {100 * best_dof:.1f} % at most "
                f"(< {100 * self.min_improvement:.0f} %)"
            )
        elif thrust_signed(s.candidate.parameter, s.value):  # a model with it gains energy
            s.reason = (
                f"not physical: {s.candidate.parameter} = {s.value:.3g} has the sign of a "
                "thrust, not of a drag"
            )
        else:
            try:
                s.candidate.augment(fit.vehicle, s.value)
            except ValueError as exc:
                s.reason = f"not physical: {str(exc).splitlines()[0]}"
                return
            s.admissible = True
            s.reason = "passes the tests; ranked below the one added"

    def _augment(self, ws: Workspace, fit: Fit, s: Scored) -> Fit:
        """Add the effect, make its parameter an unknown (linear ones), refit everything."""
        if s.edge:  # added, since the model with it is measured better; its size is a bound
            warnings.warn(
                f"{s.name} = {s.value:.4g} lies at {s.edge}: the true size may lie beyond it, "
                "and is not measured (no standard error is reported)",
                stacklevel=2,
            )
        vehicle = vehicle_with(fit.vehicle, s.refit)
        vehicle = s.candidate.augment(vehicle, s.value)
        unknowns = list(fit.unknowns)
        if s.candidate.linear:
            unknowns.append(s.candidate.parameter)
        return refit(ws, vehicle, unknowns)

    # -- scores ---------------------------------------------------------------------------------
    def _scores(self, ws: Workspace, fit: Fit) -> tuple[dict, dict]:
        """Held-out errors of a fit (velocity NRMSE in free run, :data:`FALLBACK_S` ahead and
        one step, each with the ``{dof: t}`` of the DOFs that diverged under
        :func:`nnid.evaluation.evaluate.diverged_key`, as ``metrics.json`` has them; force
        residual RMS) and MATLAB ``resid`` analysis of its force residual against the input
        forces. A k-step score that diverged was a bare null, told in the report from one
        not measured by nothing."""
        val, dofs = ws.val, self.dofs_
        r = force_residual(ws, fit.vehicle)
        k = max(round(FALLBACK_S / frame_step(val)), 1)
        errors: dict = {}
        for name, mode in (("free_run", "free_run"), ("k_step", k), ("one_step", "one_step")):
            scores, diverged = self._velocity_scores(ws, fit.vehicle, mode)
            errors[MODE_KEYS[name]] = scores
            errors[diverged_key(name)] = diverged
        # relative to the force the vehicle file gives, before and after alike: the fit's own
        # (through an added deadband or lag) moved the total's yardstick with the effect
        errors["force_rmse"] = force_rmse(r, ws.arrays(self.vehicle, "val")["tau"], dofs)
        tau = nominal_forces(val, fit.vehicle)
        inputs = {f"tau_{f}": tau[:, i] for i, f in enumerate(FORCES) if np.any(tau[:, i])}
        exp = ws.data_val["experiment"]
        analysis = {
            d: correlation_analysis(r[:, i], inputs, exp) for i, d in enumerate(DOFS) if d in dofs
        }
        return errors, analysis

    def _unexplained(self, ws: Workspace, fit: Fit) -> dict[str, list]:
        """Per analysed DOF, the structure left in the final fit's held-out force residual that
        noise cannot explain (:mod:`nnid.loop.unexplained`); empty lists where there is none."""
        from nnid.datasets.preprocess import savgol_window

        r = force_residual(ws, fit.vehicle)
        data = ws.data_val
        dt = log_step(data["t"], data["experiment"])
        derived = any(s.step == "derive accelerations" for s in self.cleaning_.steps)
        # the SG derivative's span sets how far measurement noise alone correlates
        window = savgol_window(self.savgol_window, 1.0 / dt, self.savgol_order) if derived else 1
        tau = nominal_forces(ws.val, fit.vehicle)
        inputs = {f"tau_{f}": tau[:, i] for i, f in enumerate(FORCES) if np.any(tau[:, i])}
        velocities = {d: data["nu"][:, i] for i, d in enumerate(DOFS) if d in ws.val}
        memo: dict = {}  # the signals' autocorrelations, shared by the DOFs of this residual
        return {
            d: unexplained_structure(
                r[:, i],
                inputs,
                velocities,
                data["experiment"],
                dt,
                window,
                self.savgol_order,
                self.alpha,
                force_rms=float(np.sqrt(np.mean(tau[:, i] ** 2))),
                memo=memo,
            )
            for i, d in enumerate(DOFS)
            if d in self.dofs_
        }

    # -- outputs --------------------------------------------------------------------------------
    def free_runs(self) -> tuple[np.ndarray, pd.DataFrame, pd.DataFrame, pd.DataFrame, list[str]]:
        """Held-out time, measured velocities, baseline and final free runs, excited DOFs."""
        from nnid.datasets.preprocess import excited_dofs

        val = self.workspace_.val
        runs = [
            predict(fit.vehicle, val, "free_run", self.dofs_) for fit in (self.baseline_, self.fit_)
        ]
        dofs = excited_dofs(val, [d for d in self.dofs_ if d in val])
        return val["t"].to_numpy(), val, runs[0], runs[1], dofs

    @property
    def added(self) -> list[str]:
        return [s.name for s in self.added_]

    def _final_effect(self, scored: Scored) -> dict:
        """An added effect as the final model holds it: a linear effect's parameter is refitted
        jointly in every later pass, so its value ± s.e. come from the final fit, the pass's own
        beside them; a 1-D-searched effect keeps its pass's value. The s.e. is the larger of
        the fit's widened by √ of the final residual's correlation time (as each pass widens
        its candidate's by the residual with the candidate in) and the run-clustered one
        (:func:`~nnid.loop.diagnose.run_stderr`)."""
        out = scored.as_dict()
        param = scored.candidate.parameter
        if param is None or param not in self.fit_.unknowns:
            return {**out, "from": "its pass (a 1-D search, not refitted later)"}
        k = self.fit_.unknowns.index(param)
        base = Parts.from_vehicle(self.vehicle).get(param)
        cand = scored.candidate
        se = float(self.fit_.stderr[k]) * self.final_widen_
        if self.run_stderr_ is not None:
            se = max(se, float(self.run_stderr_[k]))
        se *= abs(cand.value_scale(self.vehicle))
        return {
            **out,
            "params": {"value": cand.value(float(self.fit_.theta[k]) - base, self.vehicle)},
            "stderr": {"value": se if np.isfinite(se) else None},
            "pass_params": out["params"],
            "pass_stderr": out["stderr"],
            "from": "the final joint refit",
        }

    @property
    def stopped_at_limit(self) -> bool:
        """True where the loop ended because ``max_effects`` were added, not because a pass
        found nothing to add: candidates beyond were not tested."""
        return not self.steps_ or self.steps_[-1].added is not None

    def as_dict(self) -> dict:
        """``loop.json`` (ARCHITECTURE.md): baseline, before, ranked candidates, added, after."""
        first = self.steps_[0] if self.steps_ else Step([], None, [])
        widen = float(np.sqrt(self.workspace_.tau_corr))
        return {
            "vehicle": self.vehicle.name,
            "baseline": f"{self.vehicle.name}: vehicle file, damping structure refitted "
            f"({len(self.baseline_.unknowns)} coefficients)",
            "before": self.before_,
            # the candidates the data do not excite measure nothing: named in each step's
            # "not_excited", not listed among the scored ones (a BlueROV1 log without u or v
            # has 165 of them)
            "candidates": [s.as_dict() for s in _scored(first)[: self.report_candidates]],
            # the family the Bonferroni correction is over: the candidates scored (and the
            # 1-D searches that found nothing better); those not scored are counted apart
            "candidates_tested": first.tested,
            "candidates_not_excited": sum(not s.excited for s in first.ranked),
            "candidates_not_identifiable": sum(not s.identifiable for s in first.ranked),
            "candidates_not_finite": sum(not s.finite for s in first.ranked),
            # among those tested: the 1-D searches that found no better fit (nothing to rank)
            "candidates_no_better_fit": len(first.no_better_fit),
            "added": self.added,
            "after": self.after_,
            # the reported model's held-out error in the mode the last added effect was gated
            # in, beside the gated model's: "after" is a refit the gate never simulated
            "after_vs_gate": self.after_vs_gate_,
            # the train pipeline's word for a held-out part that fitting read: with an effect
            # added, the runs that measured "after" also ranked and gated it (None: nothing
            # was added, and "after" is the baseline's, fitted on the training part alone)
            "validation_used_for": HELD_OUT_USE if self.added_ else None,
            "stopped": "max_effects" if self.stopped_at_limit else "no candidate passed",
            "steps": [
                {
                    "gate": gate,
                    "added": None if st.added is None else self._final_effect(st.added),
                    "top": [s.as_dict() for s in _scored(st)[:10]],
                    "not_excited": [s.name for s in st.ranked if not s.excited],
                    "not_identifiable": [s.name for s in st.ranked if not s.identifiable],
                    "not_finite": [s.name for s in st.ranked if not s.finite],
                    # counted in "tested", ranked nowhere: the searches that found nothing
                    "no_better_fit": st.no_better_fit,
                    "tested": st.tested,
                    "sindy": st.sindy,
                    **gate_verdicts(st),
                }
                for st, gate in zip(self.steps_, self.gates_, strict=True)
            ],
            # standard errors widened by the residual's correlation time, as the passes' are
            "baseline_params": {
                n: {"value": float(v), "stderr": float(s) * widen if np.isfinite(s) else None}
                for n, v, s in zip(
                    self.baseline_.unknowns,
                    self.baseline_.theta,
                    self.baseline_.stderr,
                    strict=True,
                )
            },
            "residual_analysis": {
                "before": {d: c.as_dict() for d, c in self.residuals_before_.items()},
                "after": {d: c.as_dict() for d, c in self.residuals_after_.items()},
            },
            "settings": {
                "alpha": self.alpha,
                "max_effects": self.max_effects,
                "autocorrelation_time": self.workspace_.tau_corr,
                "split": self.split_,
                "warmup_s": self.warmup_s,
                "gate_horizon_s": self.gate_horizon_s,
                "k_step_s": FALLBACK_S,
                "dofs": list(self.dofs_),
                "min_improvement": self.min_improvement,
                "min_gate_gain": self.min_gate_gain,
                "gate_checks": self.gate_checks,
                "filter_lambda": self.filter_lambda,
                "zoh_midpoint": self.zoh_midpoint,
            },
            "unexplained": {
                d: describe(DOF_WORD[d], found, self.stopped_at_limit)
                for d, found in self.unexplained_.items()
                if found
            },
            "unexplained_correlates": {d: as_records(f) for d, f in self.unexplained_.items()},
            "data": {
                "gaps": self.gaps_,
                "cleaning": self.cleaning_.to_dict()["steps"],
                "rows_masked": self.cleaning_.rows_removed,
            },
            "hybrid_opinion": self.hybrid_opinion_,
            "warnings": self.warnings_,
            "seconds": self.seconds_,
        }


#: what the held-out part was used for where an effect was added (``validation_used_for``)
HELD_OUT_USE = "ranking the candidates and choosing the effects added (simulation gate)"

#: the verdict's start for an admissible candidate ranked below the ``gate_checks`` that the
#: gate simulated, where none of those was added
NOT_GATED = "not gated (beyond gate_checks"

#: the simulation gate's verdicts on a candidate it turned down (``gate_turned_down`` holds the
#: first, ``gate_refused`` the others): no gain in the held-out simulation; a one-step error
#: grown past :data:`MAX_WORSENING` times; a refit (the candidate's, or the joint one) that
#: left the physical range
NO_GAIN = "error does not improve"
ONE_STEP_GROWS = "held-out one-step error grows"
NOT_PHYSICAL = "refit not physical"

#: the verdict of a candidate that passed every test but the simulation gate, which had no
#: simulation to compare (the baseline's held-out one diverges at every horizon)
UNJUDGED = "the held-out simulation diverges even one step ahead: nothing to compare"


def thrust_signed(key: str | None, value: float) -> bool:
    """Whether ``key`` (``"Z:w"``, ``"Z:w*abs(w)"``) is a diagonal damping coefficient and
    ``value`` gives it the sign of a thrust: D(ν) dissipates only with these negative (the
    force opposes the DOF's own speed; Weiss eq. 45, D(ν)ν = −τ_D(ν))."""
    force, _, term = (key or "").partition(":")
    dof = DOFS[FORCES.index(force)] if force in FORCES else None
    return dof is not None and term in (dof, f"{dof}*abs({dof})") and value > 0


def _warn_unphysical_damping(fit: Fit, widen: float) -> None:
    """A refitted diagonal damping coefficient with the sign of a thrust: said, since a model
    with it gains energy in free run (the log does not determine that coefficient). Its s.e.
    widened by ``widen`` (√ of the residual's correlation time), as loop.json gives it (the
    warning said ± 3.8 where loop.json said ± 84)."""
    for key, value, se in zip(fit.unknowns, fit.theta, fit.stderr * widen, strict=True):
        if thrust_signed(key, value):
            warnings.warn(
                f"the baseline's refitted {key} = {value:.3g} ± {se:.2g} has the sign of a "
                "thrust, not of a drag: the log does not determine it (weak or one-sided "
                "excitation, contact), and a free run of this model can gain energy",
                stacklevel=2,
            )
