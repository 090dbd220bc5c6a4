"""A seed ensemble: copies of one model fitted with different seeds, predicting together.

A network fitted from different random starts lands in different minima whose free runs err
in different ways; the pointwise mean of their predictions is the simplest regulariser that
uses no more data (the rule of ``benchmarks/bench_nlbench.py`` on Cascaded Tanks, and of
``configs/seamor_narx_*.toml``). The selection rule is fixed in the settings, never chosen on
a test record: every seed in ``seeds`` is a member, combined by ``combine`` ("mean" or
"median", pointwise per output and sample), except that with ``drop_diverged`` a member whose
free run on the validation log diverges is left out (said in ``dropped_``; never all of them).
A kept member that goes wild on a later log is still combined (a median ranks it away, a mean
is dragged by it), and :meth:`EnsembleModel.predict` says so with a
:class:`WildMemberWarning` naming its seed (:func:`wild_members`): the numbers are the rule's,
the member is not hidden.

Members are independent fits: ``n_jobs`` > 1 fits them in that many worker processes
(joblib's loky backend, which caps each worker's OpenMP threads at its share of the cores;
the calling process's state is untouched). A member's result does not depend on where it
was fitted beyond the last bits that a thread count changes, nor do its warnings: each is
said in the calling process, named by the member's seed.
"""

from __future__ import annotations

import numbers
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import replace

import numpy as np
import pandas as pd
import torch
from sklearn.base import clone

from nnid.errors import NnidInputError
from nnid.evaluation.evaluate import DIVERGENCE_FACTOR, left_range, same_scale
from nnid.evaluation.metrics import warmup_mask
from nnid.evaluation.prediction import Replay
from nnid.models.base import AccelerationParts, NnidModel, learned_state, restore_learned
from nnid.trainers.history import Progress, staged

COMBINE = ("mean", "median")


class WildMemberWarning(UserWarning):
    """A kept member's prediction diverged or left the range of the others and the data."""


class EnsembleModel(NnidModel):
    """The pointwise ``combine`` of the predictions of ``model`` fitted once per seed.

    ``model``: an unfitted nnid model with a ``seed`` setting (NARX, state space, hybrid,
    SINDy; a config's ``[model.member]`` is one of the first three);
    ``seeds``: the members' seeds (at least two). ``members_`` are the fitted copies,
    ``member_validation_`` their validation free-run NRMSE (total; None where it diverged or
    there was no validation log), scored as :func:`nnid.evaluation.evaluate.evaluate` scores
    with ``warmup_s`` and, for a log flown under an autopilot, the ``replay`` given to
    :meth:`fit` (``nnid train`` sets its config's warm-up and passes its run's replay, so these
    are the members' validation totals of ``metrics.json``, and the members that
    ``drop_diverged`` judges are judged by the free runs reported). Members are fitted on the
    same training and validation
    logs, one after the other or (``n_jobs``) in worker processes, whose progress is then
    reported per finished member.
    """

    kind = "ensemble"

    def __init__(
        self,
        model: NnidModel,
        seeds: Sequence[int] = (0, 1, 2),
        combine: str = "mean",
        drop_diverged: bool = True,
        n_jobs: int = 1,
        warmup_s: float = 0.0,
    ) -> None:
        self.model = model
        self.seeds = seeds
        self.combine = combine
        self.drop_diverged = drop_diverged
        self.n_jobs = n_jobs
        self.warmup_s = warmup_s

    @classmethod
    def from_config(cls, spec, vehicle=None) -> EnsembleModel:
        """The ensemble of an ``[model]`` table of kind "ensemble": its ``[model.member]``
        built as its own table would be."""
        return cls(model=spec.member.build(vehicle), **spec.arguments())

    @property
    def validation_role(self) -> str | None:  # type: ignore[override]
        """The member's role and, with ``drop_diverged``, the judging of the members."""
        own = "dropping diverged members" if self.drop_diverged else None
        uses = [u for u in (getattr(self.model, "validation_role", None), own) if u]
        return ", ".join(uses) or None

    def _validation_used(self, validation: pd.DataFrame | None) -> str | None:
        """What the kept members' fits did with ``validation`` (each says its own) and,
        with ``drop_diverged`` and a validation log, the judging of the members on it."""
        own = "dropping diverged members" if self.drop_diverged and validation is not None else None
        uses = [*(m.validation_use for m in self.members_), own]
        return ", ".join(dict.fromkeys(u for u in uses if u)) or None

    def _check_settings(self) -> list[int]:
        if not isinstance(self.model, NnidModel) or "seed" not in self.model.get_params():
            raise NnidInputError(
                "an ensemble's model is an nnid model with a seed "
                "(narx, state_space, hybrid, sindy)",
                field="model",
            )
        if not self.model.seeded:
            raise NnidInputError(
                f"this {self.model.kind} model's fit does not depend on its seed, so every "
                'member would be the same model (for sindy: optimizer = "ensemble", which '
                "draws its candidate terms at random)",
                field="model",
            )
        if self.combine not in COMBINE:
            raise NnidInputError("combine is 'mean' or 'median'", field="combine")
        warmup = self.warmup_s
        # scored_rows would score the warm-up; a text or None would end in a bare TypeError
        if (
            isinstance(warmup, bool)
            or not isinstance(warmup, numbers.Real)
            or not (np.isfinite(warmup) and warmup >= 0)
        ):
            raise NnidInputError(
                f"warmup_s is 0 or more seconds, not {self.warmup_s!r}", field="warmup_s"
            )
        seeds = [int(s) for s in self.seeds]
        if len(seeds) < 2 or len(set(seeds)) != len(seeds):
            raise NnidInputError("an ensemble needs at least two different seeds", field="seeds")
        return seeds

    def fit(
        self,
        log: pd.DataFrame,
        validation: pd.DataFrame | None = None,
        progress: Progress | None = None,
        replay: Replay | None = None,
    ) -> EnsembleModel:
        """:meth:`NnidModel.fit`; ``replay``: how the logs were flown in closed loop
        (:func:`nnid.pipeline.replay_of`), or None. The members that can fly in closed loop
        (hybrids) then have their validation free runs flown under it, as
        :func:`nnid.evaluation.evaluate.evaluate` flies them with that replay: the pipeline's
        scores, by the pipeline's own rule (open loop, it scored them 0.050 and 0.051 where
        ``metrics.json`` said 0.038 and 0.042, and dropped members by runs it did not
        report)."""
        self._replay = replay  # not a setting: it is the data's, and is not saved
        try:
            return super().fit(log, validation, progress)
        finally:
            del self._replay

    def motion_columns(self, columns: Iterable[str]) -> list[str]:
        """Its members' (clones of ``model``); every motion column where ``model`` is no
        nnid model (the fit says what is wrong with it)."""
        if not isinstance(self.model, NnidModel):
            return super().motion_columns(columns)
        return self.model.motion_columns(columns)

    def acceleration_parts(self, members_scored: bool = False) -> AccelerationParts | None:
        """Its members' in the held-out parts where those score them (``members_scored``),
        the window named under ``member``: the ensemble has no force equation of its own, and a
        member's fit refuses a window too long for the training part as it starts."""
        if not members_scored or not isinstance(self.model, NnidModel):
            return None
        member = self.model.acceleration_parts()
        if member is None:
            return None
        held_out = tuple(p for p in member.parts if p in ("validation", "test"))
        return replace(member, parts=held_out, field=f"member.{member.field}")

    def _fit(self, log: pd.DataFrame, validation: pd.DataFrame | None, progress: Progress):
        seeds = self._check_settings()
        jobs = max(1, min(int(self.n_jobs), len(seeds)))
        templates = [clone(self.model).set_params(seed=seed) for seed in seeds]
        replay = getattr(self, "_replay", None)
        try:
            fitted = self._fit_members(
                templates, log, validation, jobs, progress, self.warmup_s, replay
            )
        except NnidInputError as exc:
            raise exc.within("member", self.model.get_params()) from None
        members = [m for m, _, _ in fitted]
        scores = [v for _, v, _ in fitted]
        dropped = []
        if self.drop_diverged and validation is not None:
            dropped = [s for s, v in zip(seeds, scores, strict=True) if v is None]
            if len(dropped) == len(seeds):
                dropped = []  # nothing left to predict with: keep all, their scores say why
        keep = [k for k, s in enumerate(seeds) if s not in dropped]
        self.members_ = [members[k] for k in keep]
        self.member_seeds_ = [seeds[k] for k in keep]
        self.member_validation_ = [scores[k] for k in keep]
        self.dropped_ = dropped
        self._take_shape()

    @staticmethod
    def _fit_members(
        templates,
        log,
        validation,
        jobs: int,
        progress: Progress,
        warmup_s: float = 0.0,
        replay: Replay | None = None,
    ) -> list[tuple]:
        """(member, validation free-run NRMSE, its fit's warnings) of each template, in
        ``jobs`` processes; each member's warnings said here, named by its seed (a worker
        process's own never reached the caller's record)."""
        n = len(templates)
        if jobs == 1:
            fitted = []
            for i, m in enumerate(templates):
                stage = staged(progress, f"member {i + 1}/{n}")
                fitted.append(_fit_member(m, log, validation, stage, warmup_s, replay))
                _say_member_warnings(m.seed, fitted[-1][2])
            return fitted
        from joblib import Parallel, delayed

        runs = Parallel(n_jobs=jobs, backend="loky", return_as="generator")(
            delayed(_fit_member)(m, log, validation, None, warmup_s, replay) for m in templates
        )
        fitted = []
        for i, result in enumerate(runs):
            fitted.append(result)
            _say_member_warnings(templates[i].seed, result[2])
            progress(i + 1, n, "members fitted")
        return fitted

    def _take_shape(self) -> None:
        first = self.members_[0]
        self.outputs_ = list(first.outputs_)
        self.targets_ = list(first.targets_)
        self.warmup_samples_ = max(int(m.warmup_samples_) for m in self.members_)

    def _predict(self, log: pd.DataFrame, mode: str | int) -> pd.DataFrame:
        return self._combined(
            self._said([m.predict(log, mode) for m in self.members_], log, mode, caller=4), log
        )

    def _said(
        self, predictions: list[pd.DataFrame], log: pd.DataFrame, mode: str | int, caller: int
    ) -> list[pd.DataFrame]:
        """``predictions``, as they are, after a :class:`WildMemberWarning` naming the seeds
        of the members that went wild on ``log`` (:func:`wild_members`): the combination
        keeps them (the documented rule), and a median that ranks one away would otherwise
        say nothing of it. ``caller``: the warning's stacklevel, the user's line (``predict``
        reaches here one frame deeper than a ``closed_loop`` flight)."""
        preds = np.stack([p[self.outputs_].to_numpy(np.float64) for p in predictions])
        # the rows the scores read: after each run's warm-up samples and first warmup_s
        scored = warmup_mask(log, self.warmup_s, self.warmup_samples_)
        wild = wild_members(preds, log, self.outputs_, scored)
        if wild:
            seeds = ", ".join(str(self.member_seeds_[k]) for k in wild)
            name = mode if isinstance(mode, str) else f"{mode}-step"
            what = "median ranks" if self.combine == "median" else "mean averages"
            warnings.warn(
                f"ensemble member(s) with seed {seeds}: the {name} prediction diverged or left "
                "the range of the other members and the data by more than "
                f"{DIVERGENCE_FACTOR:g} times that range; the {what} it in as it stands "
                "(member.predict(log) shows it alone)",
                WildMemberWarning,
                stacklevel=caller,
            )
        return predictions

    def _combined(self, predictions: list[pd.DataFrame], log: pd.DataFrame) -> pd.DataFrame:
        """The members' predictions of the outputs combined (``combine``)."""
        preds = np.stack([p[self.outputs_].to_numpy(np.float64) for p in predictions])
        combined = combine_members(preds, self.combine)
        return pd.DataFrame(combined, columns=self.outputs_, index=log.index)

    @property
    def closed_loop(self):
        """Where every member flies in closed loop (hybrids, Fossen models), their flights
        under an autopilot replay combined as :meth:`predict` combines their open-loop runs:
        ``closed_loop(log, replay, mode)``. The ensemble is then scored as its members are
        (members scored in closed loop beside an ensemble scored open loop read 0.038 and
        0.042 against 0.050), and kept members are those whose flights it averages. Absent
        (AttributeError) otherwise, so ``getattr(model, "closed_loop", None)`` says it."""
        members = getattr(self, "members_", None)
        if not members or not all(callable(getattr(m, "closed_loop", None)) for m in members):
            raise AttributeError("closed_loop: a member that cannot fly in closed loop")

        def fly(log: pd.DataFrame, replay, mode: str | int = "free_run") -> pd.DataFrame:
            flown = [m.closed_loop(log, replay, mode) for m in members]
            return self._combined(self._said(flown, log, mode, caller=3), log)

        return fly

    def _params(self) -> dict[str, dict[str, float | None]]:
        """The members' weights and biases together and the member count."""
        return {
            "n_members": {"value": float(len(self.members_)), "stderr": None},
            "n_params": {"value": float(self._n_params()), "stderr": None},
        }

    def _n_params(self) -> int:
        return sum(m.n_params for m in self.members_)

    def trainer_name(self) -> str | None:
        return self.members_[0].trainer_name() if hasattr(self, "members_") else None

    def describe(self) -> dict:
        return {
            **super().describe(),
            "combine": self.combine,
            "member_seeds": self.member_seeds_,
            "member_validation_free_run_nrmse": self.member_validation_,
            "dropped_seeds_diverged_on_validation": self.dropped_,
            "members": [
                {k: v for k, v in m.describe().items() if k != "params"} for m in self.members_
            ],
        }

    # -- persistence: each member's JSON state in model.json, its tensors prefixed by index ----
    def _state(self) -> tuple[dict, dict[str, torch.Tensor]]:
        states, tensors = [], {}
        for i, m in enumerate(self.members_):
            learned, own = learned_state(m)
            states.append(learned)
            tensors.update({f"member{i}.{k}": v for k, v in own.items()})
        learned = {
            "members": states,
            "member_seeds": self.member_seeds_,
            "member_validation": self.member_validation_,
            "dropped": self.dropped_,
        }
        return learned, tensors

    def _restore(self, state: dict, tensors: dict[str, torch.Tensor]) -> None:
        self.member_seeds_ = [int(s) for s in state["member_seeds"]]
        self.member_validation_ = list(state["member_validation"])
        self.dropped_ = list(state["dropped"])
        self.members_ = []
        for i, (seed, saved) in enumerate(zip(self.member_seeds_, state["members"], strict=True)):
            prefix = f"member{i}."
            own = {k[len(prefix) :]: v for k, v in tensors.items() if k.startswith(prefix)}
            self.members_.append(
                restore_learned(clone(self.model).set_params(seed=seed), saved, own)
            )
        self._take_shape()


def combine_members(preds: np.ndarray, combine: str) -> np.ndarray:
    """The pointwise ``combine`` ("mean" or "median") of members' predictions (axis 0 of
    ``preds``), the rule of :meth:`EnsembleModel.predict`, which benchmark scripts that hold
    members' free runs apply too."""
    # every member counts (the members are fixed before any score; only drop_diverged leaves
    # one out, named): a member's NaN has no rank, so the median is NaN there and scoring says
    # the ensemble diverged; a member at ±inf or 1e9 has one and is ranked, which is the median
    # rule. Never nanmedian: a silent ensemble of fewer members. Each member's own divergence
    # is in metrics.json's "members".
    if combine not in COMBINE:
        raise NnidInputError("combine is 'mean' or 'median'", field="combine")
    with np.errstate(all="ignore"):  # a member's NaN warm-up rows stay NaN
        return preds.mean(0) if combine == "mean" else np.median(preds, 0)


def wild_members(
    preds: np.ndarray, log: pd.DataFrame, outputs: Sequence[str], mask: np.ndarray
) -> list[int]:
    """Indices of the members (axis 0 of ``preds``, members × rows × ``outputs``) whose
    prediction diverged by the scores' rule (:func:`nnid.evaluation.evaluate.left_range`:
    non-finite, or :data:`DIVERGENCE_FACTOR` widths outside) against the other members'
    predictions pooled with the measured column where the log has one, on the ``mask`` rows
    where every other member is finite. A rule of the others, not of the member: with the
    data in the reference, the sane one of two members is not named for the wild one's
    range; a row where every member is NaN (an input the log lacks) blames none. A velocity
    is measured against the widest reference of its scale (:func:`same_scale`), as the scores
    judge one the data barely moves: a w the log holds at rest is no divergence when one
    member predicts a coupling of a hundredth of u's range and the others a thousandth."""
    outputs = list(outputs)
    wild = []
    for k in range(preds.shape[0]):
        others = np.delete(preds, k, axis=0)
        rows, references = {}, {}
        for c, name in enumerate(outputs):
            rows[name] = mask & np.isfinite(others[:, :, c]).all(axis=0)
            reference = others[:, rows[name], c].ravel()
            if name in log:
                measured = log[name].to_numpy(np.float64)[mask]
                reference = np.concatenate([reference, measured[np.isfinite(measured)]])
            references[name] = reference
        widths = {n: float(np.ptp(r)) if r.size else 0.0 for n, r in references.items()}
        for c, name in enumerate(outputs):
            reference = references[name]
            if rows[name].any() and reference.size:
                width = max([widths[name], *(widths[g] for g in same_scale(name, outputs))])
                if left_range(reference, preds[k, rows[name], c], width).any():
                    wild.append(k)
                    break
    return wild


#: a warning as a worker sends it back: (category, message, file, line)
Said = tuple[type[Warning], str, str, int]


def _fit_member(
    member: NnidModel,
    log: pd.DataFrame,
    validation: pd.DataFrame | None,
    progress: Progress | None = None,
    warmup_s: float = 0.0,
    replay: Replay | None = None,
) -> tuple[NnidModel, float | None, list[Said]]:
    """One member fitted, its validation free-run NRMSE and the warnings of both, each once,
    for the caller to say (a function of its own so that a worker process can run it; a
    worker's own warnings went to its stderr, never to the caller's record). A fit that fails
    says its warnings before the error."""
    caught: list[warnings.WarningMessage] = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            member.fit(log, validation, progress)
            score = _free_run_total(member, validation, warmup_s, replay)
    except BaseException:
        _say_member_warnings(member.seed, _once(caught))
        raise
    return member, score, _once(caught)


def _once(caught: Iterable[warnings.WarningMessage]) -> list[Said]:
    """The warnings caught, the first of each in order."""
    return list(dict.fromkeys((w.category, str(w.message), w.filename, w.lineno) for w in caught))


def _say_member_warnings(seed: int, said: list[Said]) -> None:
    """A member's warnings, said again in the caller's process under the caller's filters,
    each named by the member's seed, from where it was raised (whose file tells nnid's own
    from another package's notices: :func:`nnid.warning_messages.warning_messages`)."""
    for category, message, filename, lineno in said:
        warnings.warn_explicit(
            f"ensemble member with seed {seed}: {message}", category, filename, lineno
        )


def _free_run_total(
    model: NnidModel,
    log: pd.DataFrame | None,
    warmup_s: float = 0.0,
    replay: Replay | None = None,
) -> float | None:
    """The model's total free-run NRMSE on ``log``, its warm-up samples and the first
    ``warmup_s`` of each run unscored (None without a log or where it diverged), flown under
    ``replay`` where :func:`nnid.evaluation.evaluate.evaluate` flies the model so."""
    from nnid.evaluation.evaluate import evaluate

    if log is None:
        return None
    with np.errstate(all="ignore"):
        total = evaluate(model, log, ("free_run",), None, warmup_s, replay)["free_run_nrmse"]
    total = total["total"]
    return None if total is None else float(total)
