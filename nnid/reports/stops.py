"""How each training stage of a fitted model ended, read from its ``describe()`` record and
said in words, for the train and compare reports: a stage that stalled, diverged or spent its
budget is not read as one that converged."""

from __future__ import annotations

#: a trainer's stop reason in words: whether the stage ended on a criterion of convergence,
#: on a budget, or because it could not go on
STOP_WORDS = {
    "validation": "early-stopped: the validation error stopped falling",
    "goal": "reached the error goal",
    "min_grad": "converged: gradient below its minimum",
    "max_epochs": "ran out of epochs (no stop criterion met)",
    "max_seconds": "ran out of time (no stop criterion met)",
    "mu_max": "stalled: LM found no step that lowers the error (μ past its maximum)",
    "non-finite loss": "diverged: the loss became non-finite",
}

TRAINING_TITLE = "How each training stage ended"

UNDONE = "undone: validation error did not fall"


def _own_stages(describe: dict) -> list[dict]:
    """A NARX's one-step stage and free-run stages, the windows of a neural state-space
    model, the segments of a hybrid; nothing for a model fitted in one solve."""
    out: list[dict] = []
    history = describe.get("history")
    if isinstance(history, dict):
        out.append(
            {"stage": "one-step", "epochs": history["epochs"], "stop": history["stop_reason"]}
        )
    finetune = describe.get("simulation_finetune") or {}
    stops = finetune.get("stops", [])
    epochs = finetune.get("stage_epochs") or [None] * len(stops)  # a model saved before them
    for window, ran, stop in zip(finetune.get("windows", []), epochs, stops, strict=False):
        out.append({"stage": f"free run, {window}-sample windows", "epochs": ran, "stop": stop})
    if finetune and not finetune.get("kept", True):
        out.append({"stage": "free run", "epochs": finetune.get("epochs"), "stop": UNDONE})
    for stage in describe.get("stages") or []:
        if "window" in stage:
            name = f"window {stage['window'] or 'whole runs'}"
        else:
            name = f"segments of {stage.get('segment_s')} s"
        out.append({"stage": name, "epochs": stage["epochs"], "stop": stage["stop_reason"]})
    return out


def training_stages(describe: dict) -> list[dict]:
    """Every training stage of a fitted model (of each member of an ensemble, ``member`` its
    seed) as ``{"member", "stage", "epochs", "stop"}``, ``stop`` in the trainer's words."""
    if describe.get("members"):
        pairs = zip(describe["member_seeds"], describe["members"], strict=True)
        return [{"member": seed, **s} for seed, m in pairs for s in _own_stages(m)]
    return [{"member": None, **s} for s in _own_stages(describe)]


def stage_cells(stage: dict) -> list[str]:
    """[stage, epochs, how it ended] of one entry of :func:`training_stages`."""
    epochs = stage["epochs"]
    stop = stage["stop"]
    return [
        stage["stage"],
        "-" if epochs is None else str(epochs),
        STOP_WORDS.get(stop, stop or "-"),
    ]
