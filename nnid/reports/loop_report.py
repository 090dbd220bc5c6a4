"""The report of ``nnid loop``: what the residual showed, what was added and why, and the
held-out errors before and after, in sentences a person can repeat.

One self-contained HTML page (figures embedded) and a Markdown twin with the same tables.
"""

from __future__ import annotations

import html
import math
import re

import numpy as np

from nnid.datasets.gaps import GAP_STEPS
from nnid.evaluation.evaluate import diverged_columns
from nnid.physics.dofs import DOF_WORD, DOFS, FORCES
from nnid.physics.effects import parse_effect
from nnid.reports.cells import missing, number, score_cell
from nnid.reports.figures import (
    FORCE_UNITS,
    LONG_TICKS_LEFT_IN,
    UNITS,
    figure_uri,
    html_table,
    markdown_table,
    new_figure,
    page_head,
    said_list,
)
from nnid.serialization import write_json, write_text

_DIRECTION = {
    ("u", "pos"): "Forward surge thrust",
    ("u", "neg"): "Reverse surge thrust",
    ("v", "pos"): "Starboard sway thrust",
    ("v", "neg"): "Port sway thrust",
    ("w", "pos"): "Downward heave thrust",
    ("w", "neg"): "Upward heave thrust",
}


def unit(effect: str) -> str:
    """SI unit of an effect's value."""
    kind, args = parse_effect(effect)
    angular = bool(args) and args[0] in ("p", "q", "r")
    return {
        "linear_damping": "N m s/rad" if angular else "N s/m",
        "quadratic_damping": "N m s²/rad²" if angular else "N s²/m²",
        "coupled_damping": "SI",
        "thruster_installation": "× nominal",
        "buoyancy_offset": "N",
        "restoring_offset": "m",
        "current": "m/s",
        "external_bias": "N m" if angular else "N",
        "actuator_lag": "s",
        "thruster_deadband": "input units",
        "added_mass": "kg m²" if angular else "kg",
    }[kind]


def effect_sentence(candidate: dict) -> str:
    """'Upward heave thrust is 57 % ± 2 % of nominal' and the like, and the candidates the
    log cannot tell it from."""
    same = candidate.get("same_column_as") or []
    if not same:
        return _effect_words(candidate)
    return (
        f"{_effect_words(candidate)} (on this log {candidate['effect']} is the same column as "
        f"{', '.join(same)}: the data cannot tell them apart)"
    )


def _effect_words(candidate: dict) -> str:
    words = _size_words(candidate)
    if candidate.get("edge"):  # a bound, not a measurement
        words += f" (at {candidate['edge']}: the true size may lie beyond it, and is not measured)"
    return words


def _size_words(candidate: dict) -> str:
    name, value = candidate["effect"], candidate["params"]["value"]
    se = candidate["stderr"]["value"]
    kind, args = parse_effect(name)
    pm = f" ± {number(se, 2)}" if se is not None else ""
    if kind == "thruster_installation":
        what = _DIRECTION.get(
            (args[0], args[1]),
            f"{'Positive' if args[1] == 'pos' else 'Negative'} {DOF_WORD[args[0]]} moment",
        )
        # as many decimals as the s.e.'s first digit needs: 57.0 % ± 0.2 %, not ± 0 %
        places = 0 if not se or 100 * se >= 1 else min(-math.floor(math.log10(100 * se)), 3)
        pm = f" ± {100 * se:.{places}f} %" if se is not None else ""
        return f"{what} is {100 * value:.{places}f} %{pm} of nominal"
    # plain words: a size and a direction, never "-2 cm lower"
    if kind == "buoyancy_offset":
        side = "heavier" if value >= 0 else "lighter"
        return f"In water the vehicle is {number(abs(value))}{pm} N {side} than declared (W − B)"
    if kind == "restoring_offset":
        cm = f" (± {100 * se:.1g} cm)" if se is not None else ""
        side = "lower" if value >= 0 else "higher"
        return (
            f"The centre of gravity is {100 * abs(value):.2g} cm{cm} {side} than the vehicle "
            "file says"
        )
    if kind == "current":
        return f"A steady current of {number(value)}{pm} m/s flows along NED {args[0]}"
    if kind == "actuator_lag":
        return f"The thrusters lag their commands with a time constant of {number(value)}{pm} s"
    meaning = candidate["meaning"][0].upper() + candidate["meaning"][1:]
    return f"{meaning}: {name} = {number(value)}{pm} {unit(name)}"


def _diverged_text(errors: dict) -> str:
    """'in u, w from t = 12.3 s' for the free run's diverged DOFs (the earliest time)."""
    gone = errors.get("diverged", {})
    return f"in {', '.join(gone)} from t = {min(gone.values()):.1f} s" if gone else ""


def _like_for_like(result: dict) -> tuple[str, str, dict, dict]:
    """(name, key, before, after) of the held-out error to compare: the free run where
    neither fit diverges, else the k-step error, else the one-step error."""
    k_s = result["settings"].get("k_step_s", 1.0)
    for name, key in (
        ("free-run", "free_run_nrmse"),
        (f"{k_s:g} s-ahead", "k_step_nrmse"),
        ("one-step", "one_step_nrmse"),
    ):
        before, after = result["before"].get(key, {}), result["after"].get(key, {})
        if before.get("total") is not None and after.get("total") is not None:
            return name, key, before, after
    return (
        "one-step",
        "one_step_nrmse",
        result["before"]["one_step_nrmse"],
        result["after"]["one_step_nrmse"],
    )


def summary(result: dict) -> list[str]:
    """One sentence per added effect with its effect on the held-out error, or the plain
    statement that nothing significant was found. Where a free run diverges that is said, and
    before and after are compared on the first horizon at which neither diverges."""
    name, key, before, after = _like_for_like(result)
    lines = _gaps_line(result.get("data", {})) + _verdict(result, name, key, before, after)
    rest = _unexplained_lines(result)
    # the total stays last; what remains unexplained is said before it
    return lines[:-1] + rest + lines[-1:] if result["added"] else lines + rest


def _unexplained_lines(result: dict) -> list[str]:
    """Structure no effect of the vocabulary explains, per DOF, in a sentence each."""
    found = result.get("unexplained", {})
    if not found:
        return []
    lead = (
        "The added effects explain part of the held-out residual, not all of it: "
        if result["added"]
        else ""
    )
    return [f"{lead}{text[0].upper()}{text[1:]}." for text in found.values()]


def _gaps_line(data: dict) -> list[str]:
    """What was missing from the log and what became of it, or nothing for a complete log."""
    gaps = data.get("gaps", {})
    if not gaps.get("count"):
        return []
    steps = [s for s in data.get("cleaning", []) if s["step"] in GAP_STEPS]
    if steps:
        fate = "; ".join(s["detail"] for s in steps)
    else:  # a gap in a column no step of this analysis reads (z with velocities logged)
        columns = sorted({c for g in gaps.get("gaps", []) for c in g.get("columns", [])})
        fate = f"left as they are in {', '.join(columns)}: no step bridged or masked them"
    return [
        f"The log misses motion data in {gaps['count']} gaps ({gaps['seconds']:.3g} s missing, "
        f"longest {gaps['longest_s']:.3g} s): {fate}."
    ]


def _total(result: dict, when: str, key: str) -> str:
    """The held-out ``total`` of the score ``key`` before or after: the number, "diverged" or
    "not scored" (never "-" for a score that was measured and voided)."""
    scores = result[when].get(key, {})
    return score_cell(scores, "total", diverged_columns(result[when], key))


def _gate_reasons(down: list[str], refused: list[dict]) -> str:
    """Why the simulation gate turned down the candidates it met, counted by reason: nothing
    where each had no gain in simulation (the verdict says so)."""
    from nnid.loop.residual_loop import NOT_PHYSICAL, ONE_STEP_GROWS

    if not refused:
        return ""
    counts = [
        (len(down), "gained nothing in the held-out simulation"),
        (sum(r["reason"].startswith(ONE_STEP_GROWS) for r in refused),
         "made the held-out one-step error grow"),
        (sum(r["reason"].startswith(NOT_PHYSICAL) for r in refused),
         "had a refit that was not physical"),
    ]  # fmt: skip
    return ": " + ", ".join(f"{k} {why}" for k, why in counts if k)


def _verdict(result: dict, name: str, key: str, before: dict, after: dict) -> list[str]:
    diverged = [
        f"the {who} held-out free run diverges ({_diverged_text(result[when])})"
        for when, who in (("before", "baseline's"), ("after", "final model's"))
        if result[when]["free_run_nrmse"].get("total") is None
    ]
    limit = result.get("stopped") == "max_effects"
    max_effects = result.get("settings", {}).get("max_effects")
    if not result["added"] and limit:  # max_effects = 0: nothing was tested, nothing found
        return [f"No effect was tested (max_effects = {max_effects})."]
    # imported here: the train report imports this module for parameter_unit, and the residual
    # loop's import (pysindy's with it) took 0.13 s of CPU a train report has no use for
    from nnid.loop.residual_loop import UNJUDGED

    unjudged = [
        c for step in result["steps"][:1] for c in step["top"] if c.get("reason") == UNJUDGED
    ]
    if not result["added"] and unjudged:  # not "no significant effect": none could be judged
        c = unjudged[0]
        shown = len(result["steps"][0]["top"])
        why = " (see the warnings)" if result.get("warnings") else ""
        return [
            f"No effect was added, and none could be judged: of the {shown} best-ranked "
            f"candidates, {len(unjudged)} passed the F-test and the parameter test (the "
            f"strongest, {c['effect']} = {number(c['params']['value'], 4)}, removes "
            f"{100 * c['improvement']:.1f} % of the held-out force residual), but the "
            "baseline's held-out simulation diverges even one step ahead, so the simulation "
            f"gate had nothing to compare. The vehicle file's model is unstable on these "
            f"data{why}; mend it and run the loop again."
        ]
    if not result["added"]:
        total = result["before"]["free_run_nrmse"].get("total")
        where = (
            f"(held-out free-run NRMSE {number(total)})."
            if total is not None
            else f"(held-out {name} NRMSE {_total(result, 'before', key)}; {diverged[0]})."
        )
        last = result["steps"][-1] if result["steps"] else {}
        down, beyond = last.get("gate_turned_down") or [], last.get("not_gated") or []
        refused = last.get("gate_refused") or []
        if down or refused:  # significant, but the simulation gate turned each down
            more = (
                f"; {len(beyond)} more that passed were beyond gate_checks = "
                f"{result['settings'].get('gate_checks')} and not gated"
                if beyond
                else ""
            )
            gated = [*down, *(r["effect"] for r in refused)]
            # the best-ranked of both lists: the top's order (each list keeps the ranking's)
            best = next((c["effect"] for c in last.get("top", []) if c["effect"] in gated),
                        gated[0])  # fmt: skip
            n = len(gated)
            # no gain in simulation for each: said so; else what the gate did, by reason
            how = (
                "but no gain in simulation on held-out data"
                if not refused
                else "but the simulation gate added none"
            )
            lines = [
                f"No effect added: significant in the force residual, {how}. {n} "
                f"candidate{'s' if n > 1 else ''} passed the F-test, the parameter test and the "
                f"held-out residual check (the best-ranked, {best}), and the simulation gate "
                f"turned {'each' if n > 1 else 'it'} down{_gate_reasons(down, refused)}{more} "
                f"{where}"
            ]
        else:
            lines = [
                "No significant effect: no candidate of the effect vocabulary passed the F-test, "
                f"the parameter test and the held-out checks {where}"
            ]
        if total is None or total > 0.5:
            lines.append(
                "The baseline's free run does not follow the held-out data, so the model misses "
                "something none of the candidates captures (or the free run cannot judge here: "
                "see the candidate table for effects that were significant but did not improve "
                "it)."
            )
        return lines
    lines = []
    for step in result["steps"]:
        added = step["added"]
        if added is None:
            continue
        gains = {
            d: (before.get(d), after.get(d))
            for d in DOFS
            if before.get(d) is not None and after.get(d) is not None
        }
        dof = max(gains, key=lambda d: gains[d][0] - gains[d][1]) if gains else None
        gate = added.get("gate_nrmse") or {}
        if len(result["added"]) > 1 and gate.get("after") is not None:
            # several effects: each is credited with what its own pass measured, not with
            # the whole before/after (that is the total line's)
            cut = (
                f"; adding it moved the held-out {step['gate']} error from "
                f"{number(gate['before'])} to {number(gate['after'])} (NRMSE, all DOFs)"
            )
        elif dof:
            cut = (
                f"; with it the {DOF_WORD[dof]} {name} error on held-out data "
                f"{'fell' if gains[dof][1] < gains[dof][0] else 'went'} from "
                f"{number(gains[dof][0])} to {number(gains[dof][1])} (NRMSE)"
            )
        else:
            cut = ""
        lines.append(effect_sentence(added) + cut + ".")
    # a line of its own, after the effects' sentences: the demo's is quoted in the README
    lines.append(HELD_OUT_CHOSE_SHORT)
    if limit:
        lines.append(
            f"The loop stopped at max_effects = {max_effects}: the rest of the vocabulary was "
            "not tested."
        )
    if diverged:
        lines.append(
            "Before and after are compared on the "
            f"{name} error because " + " and ".join(diverged) + "."
        )
    if (after.get("total") or 0.0) > 1.0:  # a fall from 1.26 to 1.13 is no skill gained
        lines.append(
            f"The held-out {name} NRMSE stays above 1 after: the final model predicts the "
            "held-out data no better than their mean, so the fall below is that of a model "
            "without skill there."
        )
    lines.append(
        f"Total held-out {name} NRMSE: {_total(result, 'before', key)} before, "
        f"{_total(result, 'after', key)} after ({', '.join(result['added'])} added)."
    )
    return lines


#: said under the before/after table when an effect was added: the candidates were ranked and
#: gated on these runs
HELD_OUT_CHOSE = (
    "The held-out runs also ranked the candidates (by the share of their force residual each "
    "removes) and chose each added effect among the best-ranked (the simulation gate), so the "
    "errors after, free run and force residual alike, are not an independent test of it: score "
    "the fitted vehicle on runs the loop never saw for that."
)
#: the summary's line where an effect was added (the table's note says it in full)
HELD_OUT_CHOSE_SHORT = (
    "These held-out runs also ranked the candidates and chose the effects added, so the error "
    "after is not an independent test of them."
)

CANDIDATE_HEAD = ["effect", "value", "± s.e.", "unit", "p (F-test)", "held-out gain", "verdict"]
#: what each column of the candidate table means, printed under every table
CANDIDATE_COLUMNS = (
    "Columns: effect, the vocabulary name (after it, in brackets, the candidates whose column "
    "on this log is the same: the data cannot tell them apart); value ± s.e., its refitted "
    "size with the standard error as this pass screened it (an added effect's final value and "
    "s.e., from the last joint refit with the weights renewed, are the summary's); p (F-test), "
    "the significance of adding it; held-out gain, "
    "the share of the held-out force residual (weighted sum of squares over the analysed DOFs) "
    "that the refit with it removes; verdict, why it was added or not."
)


def candidate_rows(candidates: list[dict], top: int = 15) -> list[list[str]]:
    rows = []
    for c in candidates[:top]:
        se = c["stderr"]["value"]
        same = c.get("same_column_as") or []
        rows.append(
            [
                c["effect"] + (f" (= {', '.join(same)})" if same else ""),
                number(c["params"]["value"], 4),
                number(se, 2),
                unit(c["effect"]),
                number(c["significance"], 2),
                # none for a candidate the data do not excite: nothing of it is measured
                "-" if missing(c["improvement"]) else f"{100 * c['improvement']:.1f} %",
                c["reason"],
            ]
        )
    return rows


#: what each kind of candidate that was not scored is, by its ``loop.json`` key
UNSCORED = {
    "not_excited": "not excited by this data (zero regressor",
    "not_identifiable": "not identifiable beside the model (column in the span of its regressors",
    "not_finite": "not finite on the model's rows (column NaN or infinite where the fit reads data",
}


def _first_names(names: list[str]) -> str:
    """The first three of ``names``, and "..." where there are more: a line, not a table."""
    return ", ".join(names[:3]) + (", ..." if len(names) > 3 else "")


def not_excited_line(step: dict, k: int, key: str = "not_excited") -> str:
    """One line counting pass ``k``'s candidates the data do not excite (``key``
    ``"not_identifiable"``: whose column lies in the span of the model's; ``"not_finite"``:
    whose column is not finite on its rows) ("" where none): they
    measure nothing and were not tested, and listed in its table they would pad it (165 rows
    on a BlueROV1 log without u or v); their names are in ``loop.json``."""
    names = step.get(key) or []
    if not names:
        return ""
    return (
        f"{len(names)} candidate{'s' if len(names) > 1 else ''} {UNSCORED[key]}: "
        f"{_first_names(names)}): "
        f"nothing of {'them' if len(names) > 1 else 'it'} is measured, and "
        f"{'they are' if len(names) > 1 else 'it is'} not counted among the candidates tested; "
        f"the names are in loop.json (steps[{k - 1}].{key})."
    )


def no_better_fit_line(step: dict, k: int) -> str:
    """One line naming pass ``k``'s 1-D searches that ran and found no better fit ("" where
    none, or a file without the key): counted among the candidates tested (the Bonferroni
    count), they have no row in the pass's table, and unnamed a reader could not see what was
    tried."""
    names = step.get("no_better_fit") or []
    if not names:
        return ""
    one = len(names) == 1
    return (
        f"{len(names)} 1-D search{'' if one else 'es'} ({_first_names(names)}) found no better "
        "fit than the "
        f"model's over {'its' if one else 'their'} range: nothing to rank, and "
        f"{'it is' if one else 'they are'} counted among the candidates tested; the names are "
        f"in loop.json (steps[{k - 1}].no_better_fit)."
    )


def _tested_text(result: dict) -> str:
    """The count the Bonferroni correction divides α by, each pass its own (``steps[k].
    tested``; a file without them, the first pass's ``candidates_tested``); "" where no pass
    ran."""
    steps = result.get("steps") or []
    counts = [st.get("tested") for st in steps]
    if not steps or None in counts:
        tested = result.get("candidates_tested")
        if not steps or tested is None:
            return ""
        return f" over the {tested} candidates tested in the first pass, those not scored left out"
    if len(set(counts)) == 1:
        each = "" if len(counts) == 1 else " in each pass"
        return f" over the {counts[0]} candidates tested{each}, those not scored left out"
    passes = ", ".join(f"{n} in pass {k}" for k, n in enumerate(counts, 1))
    return f" over the candidates each pass tested ({passes}), those not scored left out"


def error_rows(result: dict) -> tuple[list[str], list[list[str]]]:
    head = ["held-out error", *DOFS, "total"]
    rows = []
    k_s = result["settings"].get("k_step_s", 1.0)
    for key, label in (
        ("free_run_nrmse", "free-run velocity NRMSE"),
        ("k_step_nrmse", f"{k_s:g} s-ahead velocity NRMSE"),
        ("one_step_nrmse", "one-step velocity NRMSE"),
        ("force_rmse", "force residual RMS (N, N m; total relative)"),
    ):
        for when in ("before", "after"):
            if key not in result[when]:
                continue
            # every mode's diverged DOFs, not the free run's alone: a diverged k-step score
            # read "-", as if it had not been measured
            gone = diverged_columns(result[when], key)
            cells = [score_cell(result[when][key], d, gone) for d in (*DOFS, "total")]
            rows.append([f"{label}, {when}", *cells])
    return head, rows


def markdown(result: dict) -> str:
    def table(head, rows):
        return "\n".join(markdown_table(head, rows))

    lines = [f"# Residual loop: {result.get('vehicle', '')}", ""]
    lines += [f"- {s}" for s in summary(result)]
    lines += ["", f"Baseline: {result['baseline']}.", "", "## Errors on held-out data", ""]
    lines += [table(*error_rows(result)), ""]
    if result["added"]:
        lines += [HELD_OUT_CHOSE, ""]
    if result.get("warnings"):  # the loop's own: they qualify the numbers above
        lines += ["## Warnings", "", *(f"- {w}" for w in result["warnings"]), ""]
    for k, step in enumerate(result["steps"], 1):
        lines += [f"## Pass {k}: candidates (best first)", ""]
        lines += [table(CANDIDATE_HEAD, candidate_rows(step["top"])), "", CANDIDATE_COLUMNS, ""]
        for key in UNSCORED:
            if not_excited_line(step, k, key):
                lines += [not_excited_line(step, k, key), ""]
        if no_better_fit_line(step, k):
            lines += [no_better_fit_line(step, k), ""]
        if step["sindy"]:
            lines += [f"pysindy STLSQ second opinion: {', '.join(step['sindy'])}.", ""]
        else:
            lines += ["pysindy STLSQ second opinion: no term kept.", ""]
    opinion = hybrid_opinion(result)
    if opinion:
        lines += ["## Second opinion: what a trained hybrid's network learned", "", opinion, ""]
    lines += [
        "Significance: F-test of the refit against the model without the effect, degrees of "
        "freedom shrunk by the residual's autocorrelation time "
        f"({number(result['settings']['autocorrelation_time'])} samples), Bonferroni-corrected "
        f"(α = {result['settings']['alpha']}{_tested_text(result)}); a candidate must also be a "
        "significant parameter (Caccia's percentile error ≤ 51 %), lower the held-out force "
        f"residual and lower the held-out {_gate_text(result)} error.",
        "",
    ]
    return "\n".join(lines)


#: points; the correlation bars are one line collection per panel, not a rectangle per lag
#: (drawn in three quarters of the time: every ``nnid loop`` report draws two such grids)
BAR_WIDTH = 3.0


def correlation_figure(analysis: dict, title: str) -> str:
    """Residual autocorrelation per DOF and the largest cross-correlation with an input,
    with the 99 % band (MATLAB ``resid``)."""
    dofs = [d for d in DOFS if d in analysis]
    fig, axes = new_figure(len(dofs), 2, 10.0, 1.3, fixed=True)
    for k, d in enumerate(dofs):
        c = analysis[d]
        ax = axes[k, 0]
        lags = np.arange(c.auto.size)
        # the band is drawn behind the bars it bounds, so every bar stays visible
        ax.axhspan(-c.band, c.band, color="0.85", zorder=0, label="99 % band of white noise")
        ax.vlines(lags, 0.0, c.auto, color="C0", lw=BAR_WIDTH, zorder=2)
        ax.set_ylabel(f"{d}: correlation [-]")
        ax2 = axes[k, 1]
        ax2.axhspan(-c.band, c.band, color="0.85", zorder=0)
        if c.cross:
            name = max(c.cross, key=lambda n: np.abs(c.cross[n]).max())
            ax2.vlines(c.lags, 0.0, c.cross[name], color="C1", lw=BAR_WIDTH, label=name, zorder=2)
            ax2.legend(fontsize=7, loc="upper right")
    axes[0, 0].legend(fontsize=7, loc="upper right")
    axes[0, 0].set_title(f"autocorrelation of the force residual ({title})", fontsize=9)
    axes[0, 1].set_title("cross-correlation with the strongest input", fontsize=9)
    axes[-1, 0].set_xlabel("lag [samples]")
    axes[-1, 1].set_xlabel("lag [samples]")
    return figure_uri(fig)


def free_run_figure(t, measured, before, after, dofs, window_s: float = 60.0) -> str:
    """Held-out velocities: measured, baseline and augmented free runs over the first
    ``window_s`` of the first held-out experiment."""
    keep = t - t[0] <= window_s
    if "experiment" in measured:
        keep &= (measured["experiment"] == measured["experiment"].iloc[0]).to_numpy()
    # fixed margins: the constrained layout drew the figure twice (to place, then to paint)
    fig, axes = new_figure(len(dofs), 1, 10.0, 1.5, fixed=True, left=LONG_TICKS_LEFT_IN)
    for k, d in enumerate(dofs):
        ax = axes[k, 0]
        ax.plot(t[keep], measured[d][keep], color="black", lw=1.0, label="measured")
        ax.plot(t[keep], before[d][keep], lw=0.9, label="baseline")
        ax.plot(t[keep], after[d][keep], lw=0.9, label="with added effects")
        ax.set_ylabel(f"{d} [{UNITS[d]}]")
    axes[0, 0].legend(ncol=3, fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("t [s]")
    return figure_uri(fig)


def html_page(result: dict, figures: dict[str, str]) -> str:
    """The self-contained HTML report (``figures``: data URIs by name)."""
    title = f"Residual loop: {result.get('vehicle', '')}"
    steps = []
    for k, step in enumerate(result["steps"], 1):
        added = step["added"]
        verdict = (
            f"Added <b>{html.escape(added['effect'])}</b>: {html.escape(effect_sentence(added))}."
            if added
            else "Nothing admissible: the loop stops here."
        )
        sindy = ", ".join(step["sindy"]) or "no term kept"
        steps.append(
            f"<h3>Pass {k}</h3><p>{verdict}</p>"
            + html_table(CANDIDATE_HEAD, candidate_rows(step["top"]))
            + f"<p class='note'>{html.escape(CANDIDATE_COLUMNS)}</p>"
            + "".join(
                f"<p>{html.escape(not_excited_line(step, k, key))}</p>"
                for key in UNSCORED
                if step.get(key)
            )
            + (
                f"<p>{html.escape(no_better_fit_line(step, k))}</p>"
                if step.get("no_better_fit")
                else ""
            )
            + f"<p>pysindy STLSQ over the strongest linear candidates: {html.escape(sindy)}.</p>"
        )
    imgs = "".join(
        f"<h2>{html.escape(name)}</h2><img alt='{html.escape(name)}' src='{uri}'>"
        for name, uri in figures.items()
    )
    return (
        page_head(title)
        + f"""<ul>{"".join(f"<li>{html.escape(s)}</li>" for s in summary(result))}</ul>
<p>Baseline: {html.escape(result["baseline"])}. Held-out data:
{html.escape(_split_text(result))}.</p>
<h2>Errors on held-out data, before and after</h2>
{html_table(*error_rows(result))}
{f"<p>{html.escape(HELD_OUT_CHOSE)}</p>" if result["added"] else ""}
{said_list(result.get("warnings", []))}
<h2>Candidates</h2>
{"".join(steps)}
{_opinion_html(result)}
<p>Significance is the p-value of an F-test of the refit against the model without the effect,
its degrees of freedom shrunk by the residual's autocorrelation time
({number(result["settings"]["autocorrelation_time"])} samples) and Bonferroni-corrected
(α = {result["settings"]["alpha"]}{html.escape(_tested_text(result))}). A candidate is added
only if its parameter is significant (Caccia's percentile error ≤ 51 %), it lowers the held-out
force residual, and it lowers the held-out {_gate_text(result)} error by at least
{100 * result["settings"]["min_gate_gain"]:.0f} %.</p>
{imgs}
</body></html>
"""
    )


def hybrid_opinion(result: dict) -> str:
    """One paragraph on the hybrid's learned force, named in the vocabulary, and whether it
    agrees with what the loop added ("" without a hybrid)."""
    opinion = result.get("hybrid_opinion")
    if not opinion:
        return ""
    terms = opinion["terms"][:3]
    if not any(opinion.get("force_rms", {}).values()):  # an untrained (diverged) network
        return (
            "The hybrid's network force is zero on these runs (its training diverged, or it "
            "learned nothing): it gives no second opinion."
        )
    if not terms:
        return (
            "The hybrid's network force is not explained by any single effect of the "
            "vocabulary (no term kept by the sparse regression)."
        )
    named = "; ".join(
        f"{t['effect']} ({t['meaning']}, {100 * t['share']:.0f} % of its force)" for t in terms
    )
    added = set(result.get("added", []))
    agree = [t["effect"] for t in terms if t["effect"] in added]
    verdict = (
        f"It agrees with the loop on {', '.join(agree)}."
        if agree
        else "None of them is an effect the loop added."
        if added
        else "The loop added nothing."
    )
    return (
        f"The hybrid's network force is mostly: {named}; together the terms it keeps explain "
        f"{100 * opinion['explained']:.0f} % of it. {verdict}"
    )


def _opinion_html(result: dict) -> str:
    text = hybrid_opinion(result)
    if not text:
        return ""
    return f"<h2>Second opinion: a trained hybrid</h2><p>{html.escape(text)}</p>"


def _gate_text(result: dict) -> str:
    horizon = result["settings"].get("gate_horizon_s")
    return "free-run" if horizon is None else f"{horizon:g} s-ahead simulation"


def _split_text(result: dict) -> str:
    split = result["settings"].get("split", {})
    parts = split.get("parts", {}).get("validation", [])
    names = sorted({str(p.get("experiment")) for p in parts})
    return f"{split.get('by', '?')} split, validation on {', '.join(names) or '-'}"


def write_loop_report(loop, out_dir) -> list[str]:
    """Write ``loop.json``, ``report.html`` and ``report.md`` of a fitted
    :class:`nnid.loop.residual_loop.ResidualLoop` to ``out_dir``; the summary sentences."""
    from pathlib import Path

    out_dir = Path(out_dir)
    result = loop.as_dict()
    write_json(out_dir / "loop.json", result)
    t, measured, before, after, dofs = loop.free_runs()
    figures = {
        "Held-out free run, first 60 s of the first validation experiment": free_run_figure(
            t, measured, before, after, dofs
        ),
        "Residual analysis before (held-out force residual)": correlation_figure(
            loop.residuals_before_, "baseline"
        ),
        "Residual analysis after": correlation_figure(loop.residuals_after_, "augmented"),
    }
    write_text(out_dir / "report.html", html_page(result, figures))
    write_text(out_dir / "report.md", markdown(result))
    return summary(result) + ([hybrid_opinion(result)] if result.get("hybrid_opinion") else [])


def parameter_unit(name: str) -> str:
    """The SI unit of a parameter: an added mass ``X_udot`` (kg, kg m, kg m²), a damping
    coefficient ``"X:u*abs(u)"`` (the force's unit over the basis term's), or an effect's size
    (:func:`unit`); "SI" where the name says no more."""
    added = re.fullmatch(r"([XYZKMN])_([uvwpqr])dot", name)
    if added:
        moment, angular = added[1] in "KMN", added[2] in "pqr"
        return {(False, False): "kg", (True, True): "kg m²"}.get((moment, angular), "kg m")
    force, _, term = name.partition(":")
    if force in FORCES and term:
        factors = [UNITS[v] for v in re.findall(r"[uvwpqr]", term) if v in DOFS]
        if len(factors) == len(re.findall(r"[A-Za-z_]+", term.replace("abs", ""))):
            return f"{FORCE_UNITS[force]} / ({' · '.join(factors)})"
        return "SI"  # a term of McCarter's nondimensional quantities
    try:
        return unit(name)
    except ValueError:
        return "SI"
