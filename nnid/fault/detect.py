"""Detection end to end: the monitor over a log, each alarm isolated on the window after it.

The alarm records follow the ``detect.json`` contract (ARCHITECTURE.md): time, kind, thruster and
remaining efficiency, effect, severity (the peak of the larger statistic over its threshold in the
window) and confidence.

While an isolated change persists its residual keeps the statistics above their thresholds, and
the monitor alone would not re-arm until it ends: a second fault during the first would not be
alarmed. So after an alarm whose change is isolated (a hypothesis named that leaves no more than
noise, :data:`nnid.fault.isolation.UNEXPLAINED_RATIO`), the rest of the experiment is watched
on the residual that change leaves (the fitted hypothesis taken out, fresh EWMA and CUSUM from
the end of the isolation window, the same thresholds): a new alarm there is a residual the
first change no longer explains, and is isolated on that residual (a thruster's efficiency
stated against its nominal thrust, the losses taken out before included). An alarm that is not
isolated (unexplained, not significant) leaves the monitor as it was.

A change can also go away (a snag freed, a thruster that recovers): the residual it leaves is
then its signature reversed, which isolation would name as a new change (a pull the other way,
a thruster giving 170 %), and a window that straddles the end fits no hypothesis at all. So an
alarm on rows watched on what isolated changes leave is first tested for their end
(:func:`ended_alarm`): the changes held until a time τ in the window and gone after it, the
model's own residual (or what the changes still in effect leave) healthy noise from τ on, by
the rule an isolated change passes. Such an alarm is recorded as the change(s) having ended,
and the rest is watched without them.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy.special import expit

from nnid.fault import kernel
from nnid.fault.isolation import (
    UNEXPLAINED_RATIO,
    UNEXPLAINED_SHARE,
    Diagnosis,
    isolate,
    noise_ratio,
    refit,
    signature,
)
from nnid.fault.monitor import ResidualMonitor, Trace, monitor_inputs

ALARM_FIELDS = ["experiment", "t", "kind", "thruster", "efficiency", "efficiency_low",
                "efficiency_high", "effect", "value", "stderr", "severity", "confidence",
                "explained", "residual_ratio", "hypothesis", "meaning"]  # fmt: skip


@dataclass
class DetectResult:
    trace: Trace
    alarms: list[dict]
    seconds: float


def isolated_alarm(
    monitor: ResidualMonitor,
    data: dict,
    trace: Trace,
    k: int,
    window_s: float,
    residual: np.ndarray | None = None,
    taken: Sequence[tuple[str, float]] = (),
) -> tuple[dict, Diagnosis, np.ndarray]:
    """The alarm that starts at row ``k``, isolated on [t_k, t_k + window_s]: its record, the
    diagnosis and the rows of the window. The window starts at the alarm, never before: the
    change began at or before the alarm, and healthy samples before its onset would bias the
    size of the change toward zero. ``residual`` [N, 6]: the one to isolate (the trace's own
    by default); ``taken``: the changes already taken out of it (:attr:`Rewatch.fitted`)."""
    rows = window_rows(data, k, window_s)
    residual = trace.values[:, 0:6] if residual is None else residual
    diag = isolate(monitor, data, residual, rows, list(taken))
    severity = _severity(monitor, trace, rows)
    interval = diag.efficiency_interval or (None, None)
    name = trace.experiment[k]
    record = {
        "experiment": None if name is None else str(name),
        "t": float(data["t"][k]),
        "kind": diag.kind,
        "thruster": diag.thruster,
        "efficiency": diag.efficiency,
        "efficiency_low": interval[0],
        "efficiency_high": interval[1],
        "effect": diag.effect,
        "value": diag.value,
        "stderr": diag.stderr,
        "severity": severity,
        "confidence": diag.confidence,
        "meaning": diag.meaning,
        "explained": diag.explained,
        "residual_ratio": diag.residual_ratio,
        "hypothesis": diag.hypothesis,
        "p_value": diag.p_value,
        "alternatives": diag.alternatives,
        "components": diag.components,
    }
    return record, diag, rows


def _severity(monitor: ResidualMonitor, trace: Trace, rows: np.ndarray) -> float:
    """The peak of the larger statistic over its threshold on ``rows``."""
    h_t, h_g = monitor.threshold_values
    return float(np.nanmax(np.maximum(trace.values[rows, 18] / h_t, trace.values[rows, 19] / h_g)))


@dataclass
class Change:
    """An isolated change that a :class:`Rewatch` takes out: the time of its alarm, what it was
    (:func:`said`) and its fitted hypothesis (:attr:`Diagnosis.fitted`)."""

    t: float
    said: str
    fitted: list[tuple[str, float]] = field(default_factory=list)

    @classmethod
    def of(cls, record: dict, diag: Diagnosis) -> Change:
        return cls(record["t"], said(record), list(diag.fitted))


def said(record: dict) -> str:
    """An isolated change in a few words, as a later record recalls it."""
    if record.get("thruster") and record.get("efficiency") is not None:
        return f"thruster {record['thruster']} at {100 * record['efficiency']:.0f} % of nominal"
    if record.get("components"):
        parts = ", ".join(f"{n} {c['value']:.3g}" for n, c in record["components"].items())
        return f"{record['kind']}: {parts}"
    if record.get("effect"):
        return f"{record['effect']} {record['value']:.3g}"
    return str(record.get("hypothesis"))


#: the fewest rows after the end of a change that :func:`ended_alarm` fits (as isolation needs)
ENDED_ROWS = 10


def ended_alarm(
    monitor: ResidualMonitor,
    data: dict,
    trace: Trace,
    k: int,
    window_s: float,
    rewatch: Rewatch,
    r: np.ndarray,
    left: np.ndarray,
) -> tuple[dict, list[int]] | None:
    """The alarm at row ``k`` on rows watched on what the isolated changes of ``rewatch``
    leave, as the end of some of them: its record and the changes that ended (indices into
    :attr:`Rewatch.changes`), or None where no end explains it. ``r`` and ``left`` [rows, 6]:
    the model's residual and the one watched, on the window's rows.

    The hypothesis: the changes held until a time τ of the window and ended there, so the
    residual is ``left`` before τ and what the changes still in effect leave of ``r`` from τ
    on (the model's own residual ``r`` where they all ended: a change's end is tested before
    anything else, not isolated as a new change that cancels it). τ minimises that residual's
    whitened power (at least :data:`ENDED_ROWS` rows after it); all the changes ending is tried,
    and each one alone where there are several. It explains the alarm where ``left`` is beyond
    what a named hypothesis may leave and the fit within it, by isolation's rule
    (:data:`~nnid.fault.isolation.UNEXPLAINED_RATIO` and ``UNEXPLAINED_SHARE``).
    The confidence is its posterior weight (BIC, τ its one parameter) against the changes
    persisting; the ended changes are refitted on the rows after τ, so the record states what
    is left of them (a thruster's efficiency against nominal, an effect's value)."""
    rows = window_rows(data, k, window_s)
    ok = np.isfinite(r).all(1) & np.isfinite(left).all(1) & (rows > 0)
    n = int(ok.sum())
    if n < ENDED_ROWS or not rewatch.changes:
        return None
    rows, r, left = rows[ok], r[ok], left[ok]
    dim = max(float(monitor.mask_.sum()), 1.0)

    def power(e: np.ndarray) -> np.ndarray:
        return np.sum(((e - monitor.mu_) @ monitor.whiten_.T) ** 2, axis=1)

    p_left = power(left)
    ratio_left = float(p_left.sum()) / (n * dim)
    limit = max(UNEXPLAINED_RATIO, 1.0 + UNEXPLAINED_SHARE * (ratio_left - 1.0))
    if ratio_left <= limit:
        return None  # what the changes leave is within the rule: no end to find
    changes = rewatch.changes
    sets = [list(range(len(changes)))]
    if len(changes) > 1:
        sets += [[i] for i in range(len(changes))]
    before = np.r_[0.0, np.cumsum(p_left)]  # before[j]: left's power on the rows before j
    best = None
    for gone in sets:
        kept = [f for i, c in enumerate(changes) if i not in gone for f in c.fitted]
        after_r = _left(monitor, data, rows, r, kept)
        p_after = power(after_r)
        after = np.r_[np.cumsum(p_after[::-1])[::-1], 0.0]  # after[j]: from row j on
        cost = (before + after)[: n - ENDED_ROWS + 1]
        j = int(np.argmin(cost))
        if best is None or cost[j] < best[0]:
            best = (float(cost[j]), j, gone, kept, after_r)
    cost, j, gone, kept, after_r = best
    ratio = cost / (n * dim)
    if ratio > limit:
        return None
    tau_corr = monitor.correlation_time_
    penalty = 0.5 * np.log(max(n * len(monitor.plant_.dofs_) / tau_corr, 2.0))
    confidence = float(expit((float(p_left.sum()) - cost) / (2 * tau_corr) - penalty))
    names = list(dict.fromkeys(name for i in gone for name, _ in changes[i].fitted))
    now = refit(monitor, data, after_r[j:], rows[j:], names)
    t_end = float(data["t"][rows[j]])
    which = " and ".join(f"{changes[i].t:.2f} s ({changes[i].said})" for i in gone)
    rest = "what the changes still in effect leave" if kept else "the model's own residual"
    meaning = (
        f"the change{'s' if len(gone) > 1 else ''} alarmed at {which} ended "
        f"{'by' if j == 0 else 'at about'} {t_end:.2f} s: {rest} is healthy noise after it"
    )
    thrusters = [n_ for n_ in names if n_.startswith("thruster_loss.")]
    effects = [n_ for n_ in names if n_ not in thrusters]
    record_thruster = efficiency = low = high = effect = value = stderr = None
    components = {}
    for name, fit in now.items():
        if name in thrusters:  # against nominal: what the changes kept take of it, and now
            eff = 1.0 - sum(t for n_, t in kept if n_ == name) - fit["theta"]
            components[name] = {"value": eff, "stderr": fit["se"]}
        else:
            components[name] = {"value": fit["value"], "stderr": fit["value_se"]}
    if len(thrusters) == 1 and not effects and thrusters[0] in components:
        record_thruster = thrusters[0].split(".", 1)[1]
        efficiency = components[thrusters[0]]["value"]
        half = 1.96 * components[thrusters[0]]["stderr"]
        low, high = efficiency - half, efficiency + half
    elif effects and not thrusters and components:
        # the clearest member of the ended change: its θ over the standard error now
        effect = max(
            effects, key=lambda n_: abs(_theta(changes, gone, n_)) / max(now[n_]["se"], 1e-300)
        )
        value, stderr = components[effect]["value"], components[effect]["stderr"]
    name = trace.experiment[k]
    record = {
        "experiment": None if name is None else str(name),
        "t": float(data["t"][k]),
        "kind": "model_change",
        "thruster": record_thruster,
        "efficiency": efficiency,
        "efficiency_low": low,
        "efficiency_high": high,
        "effect": effect,
        "value": value,
        "stderr": stderr,
        "severity": _severity(monitor, trace, window_rows(data, k, window_s)),
        "confidence": confidence,
        "meaning": meaning,
        "explained": 1.0 - cost / float(p_left.sum()),
        "residual_ratio": ratio,
        "hypothesis": "change_ended",
        "p_value": None,
        "alternatives": [],
        "components": components or None,
        "ended": {"t": t_end, "alarms": [changes[i].t for i in gone]},
    }
    return record, gone


def _theta(changes: list[Change], gone: list[int], name: str) -> float:
    """The sum of the fitted θ of ``name`` over the changes ``gone``."""
    return sum(t for i in gone for n, t in changes[i].fitted if n == name)


def _left(monitor, data: dict, rows: np.ndarray, r: np.ndarray, fitted: list) -> np.ndarray:
    """What the changes ``fitted`` leave of the model's residual ``r`` [N, 6] on ``rows``:
    minus their signature (:func:`nnid.fault.isolation.signature`, linear in the changes)."""
    if not fitted:
        return r.copy()
    # where a change cannot be shown (NaN) the residual is left as it was: watched blind
    # there, a later fault would pass unsaid
    return r - np.nan_to_num(signature(monitor, data, rows, fitted))


def run_names(names, codes, named: bool) -> np.ndarray:
    """The experiment of each row (``codes`` into ``names``) as the trace and the alarm records
    name it: its label, or None where the log has no experiment column (``named`` false): one
    run without a name, as :func:`nnid.datasets.preprocess.experiments` gives it, not the
    placeholder its arrays carry ("0" in batch, "" in ``--follow``)."""
    labels = np.array(names if named else [None] * len(names), dtype=object)
    return labels[np.asarray(codes, dtype=int)]


def window_rows(data: dict, k: int, window_s: float) -> np.ndarray:
    """The rows of the isolation window of an alarm at row ``k``: its experiment's on
    [t_k, t_k + window_s]."""
    t, codes = data["t"], data["experiment"]
    return np.flatnonzero((codes == codes[k]) & (t >= t[k]) & (t <= t[k] + window_s))


def explained_by_the_changes(monitor: ResidualMonitor, r: np.ndarray, left: np.ndarray) -> bool:
    """Whether an alarm on what isolated changes leave is no new change: the residual
    ``left`` [N, 6] on its window is within what a named hypothesis may leave of the model's
    residual ``r`` there (isolation's rule: the model's error grows with the first change;
    small excursions of it are not a second fault)."""
    excess = noise_ratio(monitor, r - monitor.mu_) - 1.0
    left_ratio = noise_ratio(monitor, left - monitor.mu_)
    return left_ratio <= max(UNEXPLAINED_RATIO, 1.0 + UNEXPLAINED_SHARE * excess)


class Rewatch:
    """The monitor on the residual that the isolated changes of one experiment leave (the
    module docstring), for :func:`detect` and ``detect --follow`` alike: the changes' fitted
    hypotheses, and EWMA and CUSUM started fresh at the end of the latest one's window."""

    def __init__(self, monitor: ResidualMonitor) -> None:
        self.monitor = monitor
        self.cfg = monitor._cfg(monitor.threshold_values, monitor.interval)
        self.changes: list[Change] = []
        self.state = np.zeros(kernel.STATE_SIZE)
        self.t_prev = np.nan

    @property
    def fitted(self) -> list[tuple[str, float]]:
        """The fitted hypotheses of the changes taken out."""
        return [f for c in self.changes for f in c.fitted]

    def restart(
        self, t_prev: float, change: Change | None = None, ended: Sequence[int] = ()
    ) -> None:
        """Fresh statistics after the time ``t_prev`` (the end of an alarm's window), with the
        isolated ``change`` also taken out, and the changes ``ended`` (indices into
        :attr:`changes`, :func:`ended_alarm`) no longer."""
        self.changes = [c for i, c in enumerate(self.changes) if i not in set(ended)]
        if change is not None:
            self.changes.append(change)
        self.state[:] = 0.0
        self.t_prev = float(t_prev)

    def left(self, data: dict, rows: np.ndarray, r: np.ndarray) -> np.ndarray:
        """What the changes leave of the model's residual ``r`` [N, 6] on ``rows``: minus
        their signature (:func:`nnid.fault.isolation.signature`, linear in the changes)."""
        return _left(self.monitor, data, rows, r, self.fitted)

    def step(self, ts: np.ndarray, left: np.ndarray) -> np.ndarray:
        """The statistics of the rows at times ``ts`` (after those of the last call) on the
        residual ``left``: [N, 21] as :func:`nnid.fault.kernel.run` gives them."""
        m = self.monitor
        out = kernel.watch(self.t_prev, ts, left, self.cfg, m.mu_, m.whiten_, m.s_inv_,
                           self.state, np.empty((ts.size, 21)))  # fmt: skip
        if ts.size:
            self.t_prev = float(ts[-1])
        return out


def detect(monitor: ResidualMonitor, log: pd.DataFrame, window_s: float = 10.0) -> DetectResult:
    """Every alarm on ``log`` with its isolation on the ``window_s`` seconds after it; after an
    isolated change, the monitor watches what that change leaves (the module docstring). The
    trace keeps the model's residual r; its statistics and alarms are those watched."""
    start = time.perf_counter()
    data = monitor_inputs(log, monitor.plant_)
    trace = monitor.run(log)
    values, alarm = trace.values.copy(), trace.alarm.copy()
    residual = trace.values[:, 0:6].copy()  # the residual watched, re-referenced per change
    names = run_names(data["experiment_names"], data["experiment"], "experiment" in log)
    watched = Trace(trace.t, names, values, alarm)
    t, codes = data["t"], data["experiment"]
    rewatch: dict[int, Rewatch] = {}  # per experiment
    alarms, pos = [], 0
    changed = np.zeros(t.size, dtype=bool)  # rows watched on a re-referenced residual
    while (ks := np.flatnonzero(alarm[pos:])).size:
        k = pos + int(ks[0])
        taken = []
        if changed[k]:
            w = rewatch[int(codes[k])]
            rows = window_rows(data, k, window_s)
            r = trace.values[rows, 0:6]
            # first the end of changes: a window where one ends late is otherwise within
            # what a large change may leave, and dismissed
            ended = ended_alarm(monitor, data, watched, k, window_s, w, r, residual[rows])
            if ended is not None:
                alarms.append(ended[0])
                _rewatch(w, data, residual, values, alarm, rows, changed, ended=ended[1])
                pos = int(rows[-1]) + 1
                continue
            if explained_by_the_changes(monitor, r, residual[rows]):
                alarm[k] = False  # dismissed: no record, so no mark in the trace either
                _rewatch(w, data, residual, values, alarm, rows, changed)
                pos = int(rows[-1]) + 1
                continue
            taken = w.fitted
        record, diag, rows = isolated_alarm(monitor, data, watched, k, window_s, residual, taken)
        alarms.append(record)
        pos = k + 1
        if diag.isolated:
            w = rewatch.setdefault(int(codes[k]), Rewatch(monitor))
            _rewatch(w, data, residual, values, alarm, rows, changed, Change.of(record, diag))
            pos = int(rows[-1]) + 1
    return DetectResult(watched, alarms, time.perf_counter() - start)


def _rest(data: dict, rows: np.ndarray) -> np.ndarray:
    """The rows of the experiment after ``rows``."""
    codes = data["experiment"]
    k = int(rows[-1])
    return np.arange(k + 1, int(np.flatnonzero(codes == codes[k])[-1]) + 1)


def _rewatch(w: Rewatch, data, residual, values, alarm, rows, changed, change=None, ended=()):
    """Watch ``residual`` from fresh statistics on the rest of the experiment after ``rows``
    (the window of an alarm: no new alarm within it); values and alarms rewritten there.
    ``change``: one just isolated, taken out of the model's residual there first; ``ended``:
    changes that ended (:func:`ended_alarm`), no longer taken out."""
    rest = _rest(data, rows)
    alarm[rows[0] + 1 : rows[-1] + 1] = False
    w.restart(data["t"][rows[-1]], change, ended)
    changed[rest] = bool(w.changes)  # with none left, a later alarm is a first one again
    if change is not None or len(ended):  # values' first six columns are still r
        residual[rest] = w.left(data, rest, values[rest, 0:6])
    if rest.size:
        out = w.step(data["t"][rest], residual[rest])
        values[rest, 6:20] = out[:, 6:20]
        alarm[rest] = out[:, 20] == 1
