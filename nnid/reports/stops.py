"""How each training stage of a fitted model ended, read from its ``describe()`` record and
said in words, for the train and compare reports: a stage that stalled, diverged or spent its
budget is not read as one that converged."""

from __future__ import annotations

#: a trainer's stop reason in words: whether the stage ended on a criterion of convergence,
#: on a budget, or because it could not go on
STOP_WORDS = {
    "validation": "early-stopped: the validation error stopped falling",
    "validation diverged": "stopped: every validation free run diverged, so it kept its start",
    "goal": "reached the error goal",
    "min_grad": "converged: gradient below its minimum",
    "max_epochs": "ran out of epochs (no stop criterion met)",
    "max_seconds": "ran out of time (no stop criterion met)",
    "mu_max": "stalled: LM found no step that lowers the error (μ past its maximum)",
    "non-finite loss": "diverged: the loss became non-finite",
}

TRAINING_TITLE = "How each training stage ended"

UNDONE = "undone: validation error did not fall"

DROPPED = "dropped from the ensemble: its validation free run diverged"

#: appended to a budget stop whose kept epoch is its last: the error still fell at the end
STILL_FALLING = "; still improving at its last epoch"

#: the columns of the stop table after the stage's name
HEAD = ["epochs", "kept epoch", "how it ended"]


def _own_stages(describe: dict) -> list[dict]:
    """A NARX's one-step stage and free-run stages, the windows of a neural state-space
    model, the segments of a hybrid; nothing for a model fitted in one solve."""
    out: list[dict] = []
    history = describe.get("history")
    if isinstance(history, dict):
        out.append(_recorded("one-step", history))
    finetune = describe.get("simulation_finetune") or {}
    for stage in finetune.get("stages", []):
        out.append(_recorded(f"free run, {stage.get('window')}-sample windows", stage))
    if finetune and not finetune.get("kept", True):
        out.append(_stage("free run", finetune.get("epochs"), 0, UNDONE))
    for stage in describe.get("stages") or []:
        if "window" in stage:
            name = f"window {stage['window'] or 'whole runs'}"
        else:
            name = f"segments of {stage.get('segment_s')} s"
            trained = stage.get("segment_s_trained")  # set only where the runs were shorter
            if trained is not None:
                name += f" (the longest run, {trained:.3g} s)"
        out.append(_recorded(name, stage))
    return out


def _stage(name: str, epochs: int | None, kept: int | None, stop: str) -> dict:
    return {"stage": name, "epochs": epochs, "kept": kept, "stop": stop}


def _recorded(name: str, record: dict) -> dict:
    """A stage from a trainer's history record; a model saved before the per-stage epochs (or
    the kept ones) were recorded has none, and its cells say so ("-")."""
    return _stage(name, record.get("epochs"), record.get("best_epoch"), record["stop_reason"])


def training_stages(describe: dict) -> list[dict]:
    """Every training stage of a fitted model (of each member of an ensemble, ``member`` its
    seed) as ``{"member", "stage", "epochs", "kept", "stop"}``: ``kept`` the epoch whose
    parameters the stage kept (0: its start), ``stop`` in the trainer's words. An ensemble's
    members dropped for a diverged validation free run are rows too, after the kept ones."""
    if describe.get("members"):
        pairs = zip(describe["member_seeds"], describe["members"], strict=True)
        rows = [{"member": seed, **s} for seed, m in pairs for s in _own_stages(m)]
        dropped = describe.get("dropped_seeds_diverged_on_validation") or []
        return rows + [{"member": seed, **_stage("whole fit", None, None, DROPPED)}
                       for seed in dropped]  # fmt: skip
    return [{"member": None, **s} for s in _own_stages(describe)]


def stage_cells(stage: dict) -> list[str]:
    """[stage, epochs, kept epoch, how it ended] of one entry of :func:`training_stages`; a
    stage that spent its budget says whether its error still fell at the end (kept epoch =
    the last), so a budget too small is told from a stage that had levelled off."""
    epochs, kept, stop = stage["epochs"], stage.get("kept"), stage["stop"]
    words = STOP_WORDS.get(stop, stop or "-")
    if stop in ("max_epochs", "max_seconds") and epochs and kept == epochs:
        words += STILL_FALLING
    return [
        stage["stage"],
        "-" if epochs is None else str(epochs),
        "-" if kept is None else str(kept),
        words,
    ]
