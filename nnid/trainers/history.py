"""What every iterative trainer records and reports: one ``History`` and one progress callback.

``History`` is the per-epoch record of a fit (Levenberg-Marquardt, Adam): entry 0 of ``train``,
``validation`` and ``time`` is the starting point, entry k the state after epoch k; why it
stopped; which epoch was kept. Trainer-specific series (LM's damping μ and gradient norm,
Adam's learning rate) go in ``extra``.

``Progress`` is the one callback signature for every long fit: ``progress(done, total,
message, **scores)`` (``total`` may be None when unknown). Trainers, models and the residual
loop call it; the CLI draws it as a bar. Trainers that score every epoch (Levenberg-Marquardt,
Adam) pass the epoch's mean-square objective as ``train=`` and, with validation data,
``validation=``; a model whose stages measure different things (a NARX's one-step stage, then
its free-run stage) names each stage's measure (:func:`staged`). ``nnid sweep`` on Ray Tune
reads them so that its ASHA scheduler can stop poor trials early. Every callback accepts the
keywords and may ignore them.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from numbers import Integral

from nnid.serialization import exact_float, read_exact_float

Progress = Callable[..., None]  # (done: int, total: int | None, message: str, **scores)


def silent(done: int, total: int | None, message: str, **scores: float) -> None:
    """The progress callback that reports nothing."""


def stopping_score(value: float) -> float:
    """A validation error as early stopping compares it: a non-finite one (a free run that
    diverged) is infinitely bad, so it counts as a failure and is never kept as the best.
    NaN would compare False both ways and neither count nor reset."""
    return value if math.isfinite(value) else math.inf


def staged(progress: Progress | None, stage: str, measure: str | None = None) -> Progress:
    """``progress`` with every message prefixed by ``stage`` (a fit in several stages).
    ``measure`` names what the stage's ``validation=`` score measures, in the sweep's metric
    names (``"one_step_nrmse"``, ``"k_step_nrmse"``, ``"free_run_nrmse"``; the trainer's
    mean square, so its square on the trainer's weighting): the score is passed on a second
    time as ``validation_<measure>=``, so that a sweep's early stopping compares one measure
    across trials whose stages switch measure at different epochs."""
    report = progress or silent

    def call(done: int, total: int | None, message: str, **scores: float) -> None:
        if measure is not None and "validation" in scores:
            scores = {**scores, f"validation_{measure}": scores["validation"]}
        report(done, total, f"{stage}: {message}" if message else stage, **scores)

    return call


def scored_validation(stages: Sequence[History | dict]) -> bool:
    """Whether any stage of a fit (its ``History``, or the record ``as_dict`` made of it)
    scored held-out data: its ``validation`` series holds an entry, so the epoch it kept was
    chosen on that data, even where every entry diverged and it kept its start. A fit none of
    whose stages did kept the epochs of its lowest training loss: no early stopping."""
    return any(
        len(s.validation if isinstance(s, History) else (s.get("validation") or [])) > 0
        for s in stages
    )


@dataclass
class History:
    """Per-epoch record of an iterative fit.

    ``train[k]`` and ``validation[k]`` are the mean-square residuals after epoch k (k = 0: the
    start); ``validation`` is empty without validation data. ``time[k]`` is the cumulative wall
    time in seconds at entry k. ``best_epoch`` is the epoch whose parameters were kept (the best
    validation error when there is validation data, else the lowest training error; for LM
    its last accepted step, since a rejected one changes nothing). ``extra`` holds per-epoch
    series of one trainer (``mu``, ``gradient``, ``lr``) and ``info`` scalar facts (the largest
    Jacobian block held, ...).
    """

    train: list[float] = field(default_factory=list)
    validation: list[float] = field(default_factory=list)
    time: list[float] = field(default_factory=list)
    stop_reason: str = ""
    best_epoch: int = 0
    extra: dict[str, list[float]] = field(default_factory=dict)
    info: dict[str, float | int] = field(default_factory=dict)

    @property
    def epochs(self) -> int:
        """Epochs run (accepted or not); the start is not an epoch."""
        return max(len(self.train) - 1, 0)

    @property
    def seconds(self) -> float:
        return self.time[-1] if self.time else 0.0

    def record(self, train: float, validation: float | None, seconds: float, **extra) -> None:
        """Append one entry (the start or an epoch)."""
        self.train.append(float(train))
        if validation is not None:
            self.validation.append(float(validation))
        self.time.append(float(seconds))
        for key, value in extra.items():
            self.extra.setdefault(key, []).append(float(value))

    def early_stop_reason(self) -> str:
        """Why validation stopped the fit: ``validation`` (its error stopped falling), or
        ``validation diverged`` where no validation error recorded was finite (every check's
        held-out free run left the data's range): the fit kept its start, which no validation
        error measured."""
        finite = any(math.isfinite(v) for v in self.validation)
        return "validation" if finite else "validation diverged"

    def as_dict(self) -> dict:
        """A JSON-ready summary (the series and the stop)."""
        return {
            "epochs": self.epochs,
            "stop_reason": self.stop_reason,
            "best_epoch": self.best_epoch,
            "train": list(self.train),
            "validation": list(self.validation),
            "seconds": self.seconds,
            **{k: list(v) for k, v in self.extra.items()},
            **self.info,
        }


def _numbers(value: object, what: str) -> list[float]:
    """A saved series: a list of numbers, each as :func:`~nnid.serialization.exact_float`
    wrote it (a diverged run's inf tagged, so inf again), or null (NaN: older files wrote
    every non-finite entry so)."""
    if not isinstance(value, list):
        raise TypeError(f"the history's {what} is not a list of numbers")
    return [read_exact_float(v, f"the history's {what}") for v in value]


def history_state(history: History | list[History] | None) -> dict | list | None:
    """A fit's history (one, or one per stage) as saved in ``model.json``: every field, so
    that :func:`restored_history` gives the fitted model's back (:meth:`History.as_dict` is a
    summary: no time series, the trainer's series beside the fixed keys). A non-finite entry
    is tagged (:func:`~nnid.serialization.exact_float`): written null, the inf of a validation
    run that diverged came back NaN, an undefined error instead of an infinitely bad one."""
    if isinstance(history, list):
        return [_one_state(h) for h in history]
    return _one_state(history) if isinstance(history, History) else None


def _one_state(history: History) -> dict:
    def exact(series: list[float]) -> list:
        return [exact_float(v) for v in series]

    state = asdict(history)
    for key in ("train", "validation", "time"):
        state[key] = exact(state[key])
    state["extra"] = {k: exact(v) for k, v in state["extra"].items()}
    state["info"] = {k: _fact(v) for k, v in state["info"].items()}
    return state


def _fact(value: float | int) -> float | int | dict[str, str]:
    """An ``info`` fact as saved: a count (Adam's skipped_batches) as a whole number, so that
    it comes back one, not 3.0; any other number as :func:`exact_float` writes it."""
    if isinstance(value, Integral) and not isinstance(value, bool):
        return int(value)
    return exact_float(value)


def _read_fact(value: object, what: str) -> float | int:
    """Inverse of :func:`_fact` after a JSON round trip, checked (TypeError naming ``what``)."""
    if isinstance(value, int) and not isinstance(value, bool):
        return value
    return _numbers([value], what)[0]


def restored_history(value: object) -> History | list[History] | None:
    """The inverse of :func:`history_state` after a JSON round trip, checked: a file edited by
    hand is refused at loading (TypeError), never a history that fails when read. A
    non-finite entry comes back as tagged (a diverged validation run's inf is inf again); null,
    as files written before the tag hold for every non-finite entry, is NaN."""
    if value is None:
        return None
    if isinstance(value, list):
        return [_one_history(v) for v in value]
    return _one_history(value)


def _one_history(value: object) -> History:
    if not isinstance(value, dict):
        raise TypeError("a saved history is not a mapping")
    extra, info = value.get("extra", {}), value.get("info", {})
    stop, best = value.get("stop_reason", ""), value.get("best_epoch", 0)
    if not isinstance(extra, dict) or not isinstance(info, dict):
        raise TypeError("the history's extra and info are not mappings")
    if not isinstance(stop, str) or not isinstance(best, int) or isinstance(best, bool):
        raise TypeError("the history's stop_reason is not text or its best_epoch not a count")
    return History(
        train=_numbers(value["train"], "train"),
        validation=_numbers(value["validation"], "validation"),
        time=_numbers(value["time"], "time"),
        stop_reason=stop,
        best_epoch=best,
        extra={str(k): _numbers(v, str(k)) for k, v in extra.items()},
        info={str(k): _read_fact(v, str(k)) for k, v in info.items()},
    )
