"""One scoring of any fitted model on a log: every number of every JSON output comes from here.

:func:`evaluate` predicts in each requested mode (one step, k steps, free run) and scores the
model's target columns with one rule set (ARCHITECTURE.md "JSON outputs"):

- NRMSE per column = RMSE / std of the measured signal over the scored samples; ``total`` is
  the mean over the columns the data excites (velocity DOFs that barely move are not scored:
  their NRMSE would divide by their own noise);
- scored samples exclude, in each experiment, the model's initial conditions (its
  ``warmup_samples_``, or more where the caller asks: a comparison scores every model after
  the longest of theirs, so that all are scored on the same samples; and the k − 1 further
  samples a k-step prediction needs) and the first ``warmup_s`` seconds;
- a prediction that leaves the physical range (non-finite, or more than
  :data:`DIVERGENCE_FACTOR` measured ranges outside the measured range) has diverged: that
  column scores ``None`` and is listed with the time it left, and ``total`` is ``None`` too,
  never an average that hides it; a target velocity the data barely moves (not scored) is
  checked too, against the ranges of the scored ones (:func:`unscored_divergence`);
- a split of several runs also gets each run's free-run NRMSE scored on its own
  (``free_run_nrmse_per_experiment``; a run a gap cut into pieces is one run): the pooled
  NRMSE divides by the spread of all the runs, which can hide a run that fails on an output
  it barely moves; a run whose free run leaves the physical range (judged by the split's
  range: a calm run's own is its noise) is listed in ``diverged_per_experiment``, and in
  every mode a column that diverged in one run has diverged in the pooled scores too
  (:func:`score_split`), so the pooled ``total`` that summaries, sweeps and the loop read
  never averages a diverged run;
- a score that is None without a divergence says why under ``<mode>_not_scored``
  (:func:`not_scored`: no sample after the warm-ups, a constant signal, or no output scored);
- models with a force equation also get McCarter's J (RMS force residual, eq. 4.25), J₀ (RMS of
  the force series) and their ratio, and the force RMSE per DOF.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import pandas as pd

from nnid.datasets.log import VELOCITY, check_log
from nnid.datasets.preprocess import excited_dofs, run_rows
from nnid.evaluation.metrics import exact_mean, exact_std, warmup_mask
from nnid.evaluation.prediction import check_mode, mode_steps
from nnid.physics.dofs import DOFS, FORCES

#: a prediction further than this many measured ranges outside the measured range has diverged
DIVERGENCE_FACTOR = 10.0
MODE_KEYS = {"one_step": "one_step_nrmse", "k_step": "k_step_nrmse", "free_run": "free_run_nrmse"}


def diverged_key(mode: str) -> str:
    """The key of a part's scores that holds the ``{column: t}`` of the columns that diverged
    in ``mode`` (``"free_run"``, ``"k_step"``, ``"one_step"``)."""
    return "diverged" if mode == "free_run" else f"{mode}_diverged"


#: why a score is None though nothing diverged (:func:`not_scored`)
NO_OUTPUT = "no output scored"
NO_SAMPLES = "no sample left after the warm-ups"
CONSTANT = "constant on the scored samples"


def not_scored_key(mode: str) -> str:
    """The key of a part's scores that holds the ``{column: why}`` of the columns of ``mode``
    scored None though they did not diverge (:func:`not_scored`)."""
    return f"{mode}_not_scored"


def not_scored(
    log: pd.DataFrame,
    columns: Sequence[str],
    mask: np.ndarray,
    nrmse: dict[str, float | None],
    diverged: dict[str, float],
) -> dict[str, str]:
    """``{column: why}`` of the columns whose NRMSE is None without a divergence:
    :data:`NO_SAMPLES` (nothing measured after the warm-ups) or :data:`CONSTANT` (a measured
    signal that does not vary: its NRMSE has no divisor); ``{"total": NO_OUTPUT}`` where no
    column is scored at all. Read off :func:`score_prediction`'s result, so the reason is the
    one that voided the score; a summary said "no sample left after the warm-ups" of all three."""
    if not columns:
        return {"total": NO_OUTPUT}
    out = {}
    for c in columns:
        if nrmse.get(c) is not None or c in diverged:
            continue
        y = log[c].to_numpy(np.float64)[mask]
        out[c] = NO_SAMPLES if not np.isfinite(y).any() else CONSTANT
    return out


def diverged_columns(scores: dict, key: str) -> dict[str, float]:
    """``{column: t}`` of the columns that diverged in the mode of the score ``key``
    (``free_run_nrmse``, ``k_step_rmse``, ...) of one part's scores: a None score of a column
    outside it was not scored (no samples after the warm-up, or a constant signal)."""
    return scores.get(diverged_key(key.rsplit("_", 1)[0])) or {}


def target_columns(model, log: pd.DataFrame) -> list[str]:
    """The columns a model is scored on in ``log``: its targets present in the log; vehicle
    velocities only where the data excites them."""
    targets = [c for c in model.targets_ if c in log]
    vel = [c for c in targets if c in VELOCITY]
    excited = set(excited_dofs(log, vel)) if vel else set()
    return [c for c in targets if c not in VELOCITY or c in excited]


def scored_rows(log: pd.DataFrame, warmup_s: float, initial: int) -> np.ndarray:
    """True where a sample is scored: after ``initial`` samples and ``warmup_s`` seconds of its
    experiment."""
    return warmup_mask(log, warmup_s, warmup_samples=initial)


def common_warmup(models: Sequence) -> int:
    """The initial samples of each run that every one of the fitted ``models`` can be scored
    after: the longest of their ``warmup_samples_`` (0 for none). Each model scored after its
    own scored a NARX of 4 delays on 3 samples fewer per run than a physics model: rankings
    of errors over different samples."""
    return max((int(m.warmup_samples_) for m in models), default=0)


def score_prediction(
    log: pd.DataFrame,
    predicted: pd.DataFrame,
    columns: Sequence[str],
    mask: np.ndarray,
    widths: dict[str, float] | None = None,
) -> tuple[dict[str, float | None], dict[str, float | None], dict[str, float]]:
    """(NRMSE per column and ``total``, RMSE per column and ``total``, ``{column: t}`` of the
    columns that diverged: left their measured range by :data:`DIVERGENCE_FACTOR` times that
    range, or the column's ``widths`` where given)."""
    t = log["t"].to_numpy(np.float64)
    nrmse: dict[str, float | None] = {}
    rmse: dict[str, float | None] = {}
    diverged: dict[str, float] = {}
    for c in columns:
        y = log[c].to_numpy(np.float64)[mask]
        p = predicted[c].to_numpy(np.float64)[mask]
        ok = np.isfinite(y)
        y, p, tc = y[ok], p[ok], t[mask][ok]
        if y.size == 0:
            nrmse[c] = rmse[c] = None
            continue
        width = float(np.ptp(y)) if widths is None else widths.get(c, float(np.ptp(y)))
        bad = left_range(y, p, width)
        if bad.any():
            diverged[c] = float(tc[np.flatnonzero(bad)[0]])
            nrmse[c] = rmse[c] = None
            continue
        err = math.sqrt(exact_mean((p - y) ** 2))
        std = exact_std(y)
        rmse[c] = err
        nrmse[c] = err / std if std > 0 else None
    for out in (nrmse, rmse):
        vals = [out[c] for c in columns]
        out["total"] = exact_mean(vals) if vals and all(v is not None for v in vals) else None
    return nrmse, rmse, diverged


def left_range(y: np.ndarray, p: np.ndarray, width: float) -> np.ndarray:
    """Where prediction ``p`` has diverged: non-finite, or further than
    :data:`DIVERGENCE_FACTOR` × ``width`` outside the range of the measured ``y``."""
    span = DIVERGENCE_FACTOR * max(width, 1e-12)
    return ~np.isfinite(p) | (p < float(y.min()) - span) | (p > float(y.max()) + span)


def same_scale(column: str, columns: Sequence[str]) -> list[str]:
    """The velocities among ``columns`` measured on ``column``'s scale: the linear u v w of a
    linear velocity, the angular p q r of an angular one; none for a column that is not a
    velocity. A velocity the data barely moves is judged for divergence by their widest
    range, not by its own (the data's noise, next to which any coupling reads as wild)."""
    if column not in VELOCITY:
        return []
    return [g for g in columns if g in VELOCITY and (g in "uvw") == (column in "uvw")]


def unscored_divergence(
    log: pd.DataFrame, predicted: pd.DataFrame, scored: Sequence[str], left_out: Sequence[str],
    mask: np.ndarray,
) -> dict[str, float]:  # fmt: skip
    """``{column: t}`` of the target columns left out of the score (velocities the data barely
    moves) whose prediction diverged all the same: non-finite, or more than
    :data:`DIVERGENCE_FACTOR` ranges of the widest scored column of its group (linear u v w,
    angular p q r) outside the measured range. Its own range, the data's noise, would call
    any coupling it predicts a divergence; not checking it let a free run that left for
    1e6 m/s in v keep a finite total over u."""
    t = log["t"].to_numpy(np.float64)[mask]
    out = {}
    for c in left_out:
        y = log[c].to_numpy(np.float64)[mask]
        p = predicted[c].to_numpy(np.float64)[mask]
        ok = np.isfinite(y)
        if not ok.any():
            continue
        group = same_scale(c, scored)
        cols = [log[g].to_numpy(np.float64)[mask] for g in group]
        widths = [_range(v) for v in cols if np.isfinite(v).any()]
        # judged where it was measured, as score_prediction judges a scored column: a sample
        # the log lacks (NaN, so is a one-step prediction from it) is no divergence
        bad = left_range(y[ok], p[ok], max(widths) if widths else np.inf)
        if bad.any():
            out[c] = float(t[ok][np.flatnonzero(bad)[0]])
    return out


def score_runs(
    log: pd.DataFrame,
    predicted: pd.DataFrame,
    mask: np.ndarray,
    columns_of: Callable[[pd.DataFrame], list[str]],
) -> tuple[dict[str, dict[str, float | None]], dict[str, dict[str, float]]]:
    """Each run of a split scored on its own (the columns ``columns_of`` gives for it, its
    std), as if scored alone: a split's pooled NRMSE divides by the spread of all its runs,
    so a run that barely moves an output can fail on it unseen. A run a gap cut into pieces
    (:func:`~nnid.datasets.preprocess.run_rows`) is scored as one, its pieces' squared errors
    pooled as the split's are: a piece is no run of its own (the verdict counts runs). A run
    has diverged where its prediction leaves its measured values by :data:`DIVERGENCE_FACTOR`
    ranges of the split's scored samples, not of its own (noise, in a run that barely moves
    the output). Returns
    the NRMSE of each run and ``{run: {column: t}}`` of the runs that diverged."""
    out, diverged = {}, {}
    split_range: dict[str, float] = {}  # each column's once, however many pieces need it
    for name, pos in run_rows(log):
        run = log.iloc[pos]
        cols = columns_of(run)
        # divergence is judged by the split's range (it holds the run's own): a calm run (a
        # hover, a rest between gaps; one scored sample's range is 0) has a range of noise,
        # and a drift of a centimetre per second read as a divergence of the whole split
        for c in cols:
            if c not in split_range:
                split_range[c] = split_width(log, c, mask)
        widths = {c: split_range[c] for c in cols}
        nrmse, _, left = score_prediction(run, predicted.iloc[pos], cols, mask[pos], widths)
        out[str(name)] = nrmse
        if left:
            diverged[str(name)] = left
    return out, diverged


#: fewer scored samples than this give a split no range of its own to judge divergence by:
#: the whole log's range is used (:func:`score_split`)
MIN_RANGE_SAMPLES = 20


def _range(values: np.ndarray) -> float:
    finite = values[np.isfinite(values)]
    return float(np.ptp(finite)) if finite.size else 0.0


def split_width(log: pd.DataFrame, column: str, mask: np.ndarray) -> float:
    """The range a split's predictions of ``column`` are judged by for divergence: that of
    its scored samples, or of the whole log where fewer than :data:`MIN_RANGE_SAMPLES` are
    scored (one sample's range is 0, and any error at all read as a divergence)."""
    values = log[column].to_numpy(np.float64)
    return _range(values[mask] if int(mask.sum()) >= MIN_RANGE_SAMPLES else values)


def score_split(
    log: pd.DataFrame,
    predicted: pd.DataFrame,
    columns: Sequence[str],
    mask: np.ndarray,
    columns_of: Callable[[pd.DataFrame], list[str]],
) -> tuple[dict, dict, dict[str, float], dict[str, dict], dict[str, dict[str, float]]]:
    """:func:`score_prediction` over a split, and :func:`score_runs` of its experiments when it
    has several: a pooled column that diverged in one run (:func:`score_runs`) has
    diverged in the pooled scores too (``None``, listed with the time it left, ``total``
    ``None``), however small the pooled score the other runs' spread divides it into.
    Returns the pooled NRMSE, RMSE and diverged columns, and each run's NRMSE and diverged
    columns."""
    widths = {c: split_width(log, c, mask) for c in columns}
    nrmse, rmse, diverged = score_prediction(log, predicted, columns, mask, widths)
    if len(run_rows(log)) < 2:  # one run, in pieces or not: the pooled score is its own
        return nrmse, rmse, diverged, {}, {}
    runs, left = score_runs(log, predicted, mask, columns_of)
    # only the pooled score's own columns: a run may score one the split as a whole does not
    folded = [(c, t) for cols in left.values() for c, t in cols.items() if c in columns]
    for c, t in folded:
        diverged.setdefault(c, t)
        nrmse[c] = rmse[c] = None
    if folded:
        nrmse["total"] = rmse["total"] = None
    return nrmse, rmse, diverged, runs, left


def force_scores(model, log: pd.DataFrame, mask: np.ndarray) -> dict[str, Any]:
    """McCarter's J (RMS force residual over the equation's axes, eq. 4.25), J₀ (RMS of the
    force series) and J/J₀, and the force RMSE per DOF, over the scored samples."""
    resid = model.residual(log)
    series = model.force_series(log)
    cols = [f for f in FORCES if f in resid.columns]
    r = resid[cols].to_numpy(np.float64)[mask]
    s = series[cols].to_numpy(np.float64)[mask]
    # one set of rows for both: J and J₀ over different samples would not be a ratio of errors
    both = np.isfinite(r).all(1) & np.isfinite(s).all(1)
    r, s = r[both], s[both]
    j = math.sqrt(exact_mean(r * r)) if r.size else None
    j0 = math.sqrt(exact_mean(s * s)) if s.size else None
    per_dof = {
        DOFS[FORCES.index(f)]: (math.sqrt(exact_mean(r[:, k] ** 2)) if r.size else None)
        for k, f in enumerate(cols)
    }
    return {
        "J": j,
        "J0": j0,
        "J_over_J0": j / j0 if j is not None and j0 else None,
        "force_rmse": per_dof,
    }


def evaluate(
    model,
    log: pd.DataFrame,
    modes: Sequence[str] = ("one_step", "free_run"),
    k_step: int | None = None,
    warmup_s: float = 0.0,
    autopilot=None,
    predictions: dict[str, pd.DataFrame] | None = None,
    warmup_samples: int | None = None,
) -> dict[str, Any]:
    """Scores of a fitted model on ``log`` (module docstring). ``modes`` among "one_step",
    "k_step" (``k_step`` samples ahead) and "free_run"; ``autopilot`` (a
    :class:`nnid.evaluation.prediction.Replay` of the autopilot the log was flown under) flies
    the free run and the k-step predictions of models that can fly in closed loop (those with
    a ``closed_loop`` method: physics models and hybrids) under it, so an open-loop unstable
    plant is compared as it was flown; the modes flown so are listed under ``closed_loop``.
    ``predictions``, when given, receives each mode's predicted DataFrame (for figures).
    ``warmup_samples``: the initial samples of each run left unscored where more than the
    model's own ``warmup_samples_`` (a comparison's longest, :func:`common_warmup`); fewer
    would score samples the model has no prediction for, so the model's own is the least."""
    log = check_log(log)  # before the scored rows, which are found before any prediction
    columns = target_columns(model, log)
    out: dict[str, Any] = {"columns": columns}
    initial = max(int(model.warmup_samples_), int(warmup_samples or 0))
    base = scored_rows(log, warmup_s, initial)
    out["samples"] = int(base.sum())
    for name in modes:
        if name == "k_step":
            if k_step is None:
                raise ValueError("mode 'k_step' needs k_step (samples ahead)")
            mode: str | int = check_mode(k_step)
            out["k_step"] = int(k_step)
        else:
            mode = check_mode(name)
        closed = (
            name != "one_step"
            and autopilot is not None
            and callable(getattr(model, "closed_loop", None))
        )
        pred = model.closed_loop(log, autopilot, mode) if closed else model.predict(log, mode)
        if predictions is not None:
            predictions[name] = pred
        mask = scored_rows(log, warmup_s, initial + mode_steps(mode) - 1)
        if name == "k_step":  # its first k - 1 predictions of each run need k steps of history
            out["k_step_scored"] = int(mask.sum())
        nrmse, rmse, diverged, runs, left = score_split(
            log, pred, columns, mask, lambda run: target_columns(model, run)
        )
        left_out = [c for c in model.targets_ if c in log and c in pred and c not in columns]
        gone = unscored_divergence(log, pred, columns, left_out, mask)
        if gone:  # a diverged free run, whichever column shows it, has no total
            diverged.update(gone)
            nrmse["total"] = rmse["total"] = None
        out[MODE_KEYS[name]] = nrmse
        out[MODE_KEYS[name].replace("nrmse", "rmse")] = rmse
        out[diverged_key(name)] = diverged
        why = not_scored(log, columns, mask, nrmse, diverged)
        if why:  # only where one is missing: the scores of every scored model keep their keys
            out[not_scored_key(name)] = why
        if name == "free_run" and runs:
            out["free_run_nrmse_per_experiment"] = runs
            if left:
                out["diverged_per_experiment"] = left
        if closed:
            out.setdefault("closed_loop", []).append(name)
    if model.has_force_equation:
        out.update(force_scores(model, log, base))
    return out
