"""Fault detection (issue 16): speed of the monitor and its accuracy on simulated faults.

Run by hand: ``python benchmarks/bench_detect.py speed``, ``... scenarios``, ``... ended``,
``... second`` and ``... follow [REV]``.

speed: the per-sample streaming update (median and 99th percentile over 20,000 samples,
in-process, after compilation; targets 50 µs and 200 µs) and whole logs in batch mode (target
1,000,000 samples/s), against a baseline in the same run: the same update written with NumPy and
the physics package's own objects (Actuation, the compiled right-hand side called from Python).

scenarios: the 8-thruster simulated vehicle (configs/vehicles/octorov_sim.toml) under its
controller; the model and monitor as configs/detect_fossen.toml makes them (least squares on
2 × 5 min of healthy flight, monitor calibrated on 3 × 5 min); faults at t = 20 s of 40-s runs:
every thruster at 30 % and 0 % over 5 seeds, external forces, buoyancy changes; and one hour
of healthy held-out flight for the false-alarm rate.

ended: faults that go away at 40 s (a snag freed, a thruster that recovers, ballast or a payload
released), then another fault at 52 s, 70-s runs, seeds 3001-3008: is the end said, and is the
second fault alarmed? And changes that come back only partly at 40 s (a stopped thruster back
to 80 %, one at 30 % back to 90 %, a snag half freed): are they said resized, at their new size,
with no alarm repeating after?

second: a second change after a first, with the scenarios monitor. A snag (-10 N + 1 N m yaw)
or h1 stopped from 20 s, then a ballast change of 7, 8, 9 or 10 N from 35 s, 60-s runs, seeds
1-8: is the ballast isolated (an alarm from 35 s isolated as buoyancy_offset), when, at what
size, and with what other alarms? And 12 single changes from 20 s (h1 and v2 stopped, h3 and v4
at 30 %, two snags, a tether pull, a side push, a 10 N ballast, a 6 N float, two payloads),
90-s runs, seeds 1-7 (the whole mode: about a minute of one thread, monitor included): alarms
after the first, and among the alarms dismissed as within what the change may leave
(``DetectResult.dismissed``) the highest noise ratio over the DOF equations the change leaves
alone, with the level it was judged against there (``allowed_over``; "-" where no alarm was
dismissed, so none was read).

follow: ``detect --follow`` on 10-minute streams (12,000 rows) with a change isolated at 20 s (a
thruster at 30 %, a snag, a ballast change): its signature is taken out of every 0.5 s of rows
after it, so each such flush is timed (the row whose reading flushed, read to read), over the
stream's first and last quarter of flushes (a cost growing with the rows seen shows as a
ratio above 1), with the rows each signature was computed on and the stream's time per row.
``REV`` (a git revision): the same streams also followed by that revision's nnid, in a
subprocess, and the ratio of its per-flush time to this tree's.
"""

from __future__ import annotations

import argparse
import datetime
import json
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np
import pandas as pd
from common import at_revision, machine

from nnid.datasets.faults import Fault, simulate_faults
from nnid.fault import follow as follow_module
from nnid.fault.detect import Rewatch, detect
from nnid.fault.monitor import ResidualMonitor, monitor_inputs
from nnid.models.parametric import ParametricModel
from nnid.physics import compiled
from nnid.physics.thrusters import Actuation
from nnid.trainers.least_squares import LeastSquares
from nnid.vehicle import load_vehicle

VEHICLE = Path(__file__).resolve().parents[1] / "configs" / "vehicles" / "octorov_sim.toml"


def trained(vehicle, run_s: float = 300.0) -> ResidualMonitor:
    """The monitor of the benchmark: least squares on 2 healthy runs of ``run_s`` seconds,
    calibrated on 3 others."""
    logs = [simulate_faults(vehicle, run_s, seed=s, experiment=f"h{s}") for s in range(5)]
    model = ParametricModel(
        vehicle,
        ["added_mass", "damping"],
        trainer=LeastSquares(filter_lambda=1.0),
        zoh_midpoint=True,
    ).fit(pd.concat(logs[:2], ignore_index=True))
    return ResidualMonitor(model).fit(pd.concat(logs[2:], ignore_index=True))


def numpy_update(mon, form, act, state, t, x, u):
    """The baseline: one sample with NumPy and the physics package's objects."""
    if state.get("prev") is not None:
        t0, x0, u0 = state["prev"]
        dt = t - t0
        mid = 0.5 * (x0 + x)
        tau = mon.plant_.parts_.applied(act.nominal(u0[None]))[0]
        xdot = compiled.rhs(form, mid, tau)
        r = mon.mass_ @ ((x[6:12] - x0[6:12]) / dt - xdot[6:12]) * mon.mask_
        z = mon.whiten_ @ (r - mon.mu_)
        lam = 1 - np.exp(-dt / mon.time_constant_s)
        state["ewma"] = (1 - lam) * state["ewma"] + lam * z
        state["T"] = state["ewma"] @ mon.s_inv_ @ state["ewma"]
    state["prev"] = (t, x.copy(), u.copy())


def speed() -> None:
    vehicle = load_vehicle(VEHICLE)
    mon = trained(vehicle)
    log = pd.concat(
        [simulate_faults(vehicle, 600, seed=20 + s, experiment=f"b{s}") for s in range(2)],
        ignore_index=True,
    )
    data = monitor_inputs(log, mon.plant_)
    stream = mon.stream()
    n = 20_000
    times = np.empty(n)
    for k in range(n):
        a = time.perf_counter_ns()
        stream.update(data["t"][k], data["x"][k], data["inputs"][k])
        times[k] = time.perf_counter_ns() - a
    form = mon.plant_.parts_.model(check=False).feature_form()
    act = Actuation(mon.plant_.vehicle)
    state = {"ewma": np.zeros(6)}
    base = np.empty(2000)
    for k in range(base.size):
        a = time.perf_counter_ns()
        numpy_update(mon, form, act, state, data["t"][k], data["x"][k], data["inputs"][k])
        base[k] = time.perf_counter_ns() - a
    big = pd.concat([log] * 10, ignore_index=True)
    big["experiment"] = np.repeat([f"e{i}" for i in range(20)], len(log) // 2)
    big_data = monitor_inputs(big, mon.plant_)
    cfg = mon.threshold_values
    kernel_s = min(
        _timed(lambda: mon._pass(big_data, mon.mu_, mon.whiten_, mon.s_inv_, cfg, mon.interval))
        for _ in range(3)
    )
    whole_s = min(_timed(lambda: mon.run(big)) for _ in range(2))
    one = {**big_data, "experiment": np.zeros_like(big_data["experiment"])}
    one_s = min(
        _timed(lambda: mon._pass(one, mon.mu_, mon.whiten_, mon.s_inv_, cfg, mon.interval))
        for _ in range(3)
    )
    print(f"machine: {machine(numba=numba.__version__)}; date {datetime.date.today()}")
    print(f"per-sample update: median {np.median(times) / 1e3:.2f} us, 99th percentile "
          f"{np.percentile(times, 99) / 1e3:.2f} us (target 50 / 200 us)")  # fmt: skip
    print(f"NumPy baseline: median {np.median(base) / 1e3:.1f} us "
          f"({np.median(base) / np.median(times):.0f}x the compiled update)")  # fmt: skip
    print(f"batch, arrays in memory: {len(big) / kernel_s:,.0f} samples/s over {len(big):,} "
          f"samples; from the DataFrame (velocities read, inputs mapped): "
          f"{len(big) / whole_s:,.0f} samples/s (target 1,000,000)")  # fmt: skip
    print(f"one experiment of {len(big):,} samples (one thread): {len(big) / one_s:,.0f} samples/s")
    print(f"NumPy baseline as samples/s: {1e9 / np.median(base):,.0f}")


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


#: the faults besides thruster losses, from 20 s (scenarios; some of them single changes in
#: second)
OTHERS = {
    "tether pull -15 N surge": Fault("external", 20.0, force=(-15, 0, 0, 0, 0, 0)),
    "side push 10 N sway": Fault("external", 20.0, force=(0, 10, 0, 0, 0, 0)),
    "snag -8 N + 1.5 N m yaw": Fault("external", 20.0, force=(-8, 0, 0, 0, 0, 1.5)),
    "payload 10 N heavy": Fault("effect", 20.0, effect="buoyancy_offset", value=10.0),
    "float 6 N light": Fault("effect", 20.0, effect="buoyancy_offset", value=-6.0),
    "payload 4 N heavy": Fault("effect", 20.0, effect="buoyancy_offset", value=4.0),
    "payload 2 kg, 4 N lift (W-B +15.6 N)": Fault("payload", 20.0, mass=2.0, value=4.0),
    "payload 3 kg, 25 N lift (W-B +4.4 N)": Fault("payload", 20.0, mass=3.0, value=25.0),
}


def scenarios() -> None:
    vehicle = load_vehicle(VEHICLE)
    t0 = time.perf_counter()
    mon = trained(vehicle)
    print(f"machine: {machine(numba=numba.__version__)}; date {datetime.date.today()}")
    print(f"thresholds {mon.threshold_values}, calibrated on {mon.calibration_['hours']:.3f} h")
    act = Actuation(vehicle)
    rows = []
    for seed in range(5):
        for eff in (0.3, 0.0):
            for i, name in enumerate(act.channels):
                fault = Fault("thruster", 20.0, thruster=name, efficiency=eff)
                log = simulate_faults(vehicle, 40, faults=[fault], seed=1000 + 100 * seed + i)
                alarms = [a for a in detect(mon, log).alarms if a["t"] >= 20.0]
                early = [a for a in detect(mon, log).alarms if a["t"] < 20.0]
                a = alarms[0] if alarms else {}
                lost = (1 - eff) * np.abs(act.thrusts(log.filter(like="cmd_").to_numpy())[:, i])
                visible = log["t"][(log["t"] >= 20.0) & (lost >= 2.0)].min()
                rows.append(
                    {
                        "seed": seed,
                        "thruster": name,
                        "truth": eff,
                        "alarm_t": a.get("t"),
                        "early_alarms": len(early),
                        "later_alarms": max(len(alarms) - 1, 0),
                        "visible_t": visible,
                        "named": a.get("thruster") == name,
                        "efficiency": a.get("efficiency"),
                        "in_interval": a.get("efficiency") is not None
                        and a["efficiency_low"] - 1e-9 <= eff <= a["efficiency_high"] + 1e-9,
                    }
                )
    df = pd.DataFrame(rows)
    delay = df["alarm_t"] - 20.0
    deadline = df["visible_t"].where(df["visible_t"].notna(), 20.0) + 1.0
    err = (df["efficiency"] - df["truth"]).abs()
    print(f"thruster faults: {len(df)} runs (8 thrusters x 2 sizes x 5 seeds)")
    print(f"  detected: {df['alarm_t'].notna().mean():.3f}; named right: {df['named'].mean():.3f}")
    print(f"  delay after the fault: median {delay.median():.2f} s, within 1 s "
          f"{(delay <= 1.0).mean():.3f}, max {delay.max():.2f} s")  # fmt: skip
    print(f"  within 1 s of the fault or of the lost thrust reaching 2 N: "
          f"{(df['alarm_t'] <= deadline).mean():.3f}")  # fmt: skip
    inside = df["in_interval"].mean()
    print(f"  efficiency error: median {err.median():.3f}, max {err.max():.3f}, within 0.1 "
          f"{(err <= 0.1).mean():.3f}; truth in the 95 % interval {inside:.3f}")  # fmt: skip
    print(f"  alarms before the fault: {df['early_alarms'].sum()}")
    # one fault, one alarm: detect re-watches what an isolated change leaves, and a later
    # alarm there would be a second fault that is not in the log
    print(f"  alarms after the first: {df['later_alarms'].sum()}")
    for label, fault in OTHERS.items():
        for seed in (1, 2, 3):
            log = simulate_faults(vehicle, 40, faults=[fault], seed=2000 + seed)
            alarms = [a for a in detect(mon, log).alarms if a["t"] >= 20.0]
            a = alarms[0] if alarms else None
            if a is None:
                print(f"  {label} seed {seed}: no alarm")
                continue
            size = a["value"] if a["value"] is not None else a["efficiency"]
            what = a["effect"] or a["thruster"]
            # None: an alarm not judged (too few samples in its window), no confidence measured
            confidence = "not measured" if a["confidence"] is None else f"{a['confidence']:.2f}"
            print(f"  {label} seed {seed}: t {a['t']:.2f} s, {a['kind']}, {what} = {size:.3g}, "
                  f"confidence {confidence}, "
                  f"alarms after it {len(alarms) - 1}")  # fmt: skip
    healthy = pd.concat(
        [simulate_faults(vehicle, 600, seed=5000 + s, experiment=f"q{s}") for s in range(6)],
        ignore_index=True,
    )
    fa = mon.false_alarms(healthy)
    lo, hi = fa["interval"]
    print(f"healthy held-out: {fa['alarms']} alarms in {fa['hours']:.2f} h; rate "
          f"{fa['rate_per_hour']:.3g}/h, 95 % interval {lo:.3g}-{hi:.3g}/h "
          f"(target {mon.false_alarm_per_hour:g}/h)")  # fmt: skip
    print(f"total {time.perf_counter() - t0:.0f} s")


#: a fault from 20 s that ends at 40 s, then another from 52 s, in 70-s runs
SNAG = (-10, 0, 0, 0, 0, 1.0)
ENDED = {
    "snag freed": lambda: [Fault("external", 20.0, force=SNAG, end=40.0),
                           Fault("thruster", 52.0, thruster="h1", efficiency=0.3)],
    "h1 at 30 % recovers": lambda: [Fault("thruster", 20.0, thruster="h1", efficiency=0.3,
                                          end=40.0), Fault("external", 52.0, force=SNAG)],
    "v2 stopped, restarts": lambda: [Fault("thruster", 20.0, thruster="v2", efficiency=0.0,
                                           end=40.0), Fault("external", 52.0, force=SNAG)],
    "10 N ballast dropped": lambda: [Fault("effect", 20.0, effect="buoyancy_offset", value=10.0,
                                           end=40.0), Fault("external", 52.0, force=SNAG)],
    "2 kg payload released": lambda: [Fault("payload", 20.0, mass=2.0, value=4.0, end=40.0),
                                      Fault("external", 52.0, force=SNAG)],
}  # fmt: skip


#: a change from 20 s that comes back only partly at 40 s, then a snag from 52 s, in 70-s runs:
#: the faults, what the change is after 40 s (a thruster's efficiency, or external_bias.u), and
#: the kind of the fault from 52 s
PARTIAL = {
    "v2 stopped, back to 80 %": (lambda: [
        Fault("thruster", 20.0, thruster="v2", efficiency=0.0, end=40.0),
        Fault("thruster", 40.0, thruster="v2", efficiency=0.8),
        Fault("external", 52.0, force=SNAG)], 0.8, "external_force"),
    "h1 at 30 %, back to 90 %": (lambda: [
        Fault("thruster", 20.0, thruster="h1", efficiency=0.3, end=40.0),
        Fault("thruster", 40.0, thruster="h1", efficiency=0.9),
        Fault("external", 52.0, force=SNAG)], 0.9, "external_force"),
    "snag -10 N, half freed": (lambda: [
        Fault("external", 20.0, force=SNAG, end=40.0),
        Fault("external", 40.0, force=tuple(0.5 * f for f in SNAG)),
        Fault("thruster", 52.0, thruster="h1", efficiency=0.3)], -5.0, "thruster_loss"),
}  # fmt: skip


def _others(alarms: list[dict], *counted: dict | None) -> int:
    """The alarms of a run besides those ``counted`` (each at most once: the alarm of a change's
    end can also be the first alarm after the second fault's onset)."""
    ids = {id(a) for a in counted if a is not None}
    return sum(id(a) not in ids for a in alarms)


def ended() -> None:
    """Faults that go away: is the end said (hypothesis change_ended, after 40 s), a recovered
    thruster measured at its nominal thrust, and the fault from 52 s alarmed after it? And
    changes that come back only partly: said resized (hypothesis change_resized) at their new
    size, not ended, and not alarmed again?"""
    vehicle = load_vehicle(VEHICLE)
    t0 = time.perf_counter()
    mon = trained(vehicle)
    seeds = range(3001, 3009)
    print(f"machine: {machine(numba=numba.__version__)}; date {datetime.date.today()}")
    print("| fault, ended at 40 s | runs | end said | end time (median, s) | recovered "
          "thruster (% of nominal) | second fault alarmed | other alarms |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for label, faults in ENDED.items():
        said, times, effs, second, other = 0, [], [], 0, 0
        for seed in seeds:
            alarms = detect(mon, simulate_faults(vehicle, 70, faults=faults(), seed=seed)).alarms
            ends = [a for a in alarms if a.get("hypothesis") == "change_ended"]
            if ends:
                said += 1
                times.append(ends[0]["ended"]["t"])
                if ends[0]["efficiency"] is not None:
                    effs.append(100 * ends[0]["efficiency"])
            late = [a for a in alarms if a["t"] >= 52.0 and all(a is not e for e in ends[:1])]
            second += bool(late)
            other += _others(alarms, alarms[0] if alarms else None, *ends[:1], *late[:1])
        eff = f"{min(effs):.0f}-{max(effs):.0f}" if effs else "-"
        when = f"{np.median(times):.2f}" if times else "-"
        print(f"| {label} | {len(seeds)} | {said} | {when} | {eff} | {second} | {other} |")
    print()
    print("| change from 20 s, partly back at 40 s | runs | said resized | resize time (median, "
          "s) | size said (range) | truth in its 95 % interval | said ended | second fault "
          "alarmed and named | other alarms |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|")
    for label, (faults, truth, then) in PARTIAL.items():
        said, times, sizes, inside, ends, second, other = 0, [], [], 0, 0, 0, 0
        for seed in seeds:
            alarms = detect(mon, simulate_faults(vehicle, 70, faults=faults(), seed=seed)).alarms
            resized = [a for a in alarms if a.get("hypothesis") == "change_resized"]
            ends += any(a.get("hypothesis") == "change_ended" for a in alarms)
            if resized:
                said += 1
                a = resized[0]
                times.append(a["resized"]["t"])
                if a["thruster"] is not None:
                    size, lo, hi = 100 * a["efficiency"], a["efficiency_low"], a["efficiency_high"]
                else:
                    u = a["components"]["external_bias.u"]
                    size, lo, hi = (
                        u["value"],
                        u["value"] - 1.96 * u["stderr"],
                        u["value"] + 1.96 * u["stderr"],
                    )
                sizes.append(size)
                inside += lo - 1e-9 <= truth <= hi + 1e-9
            late = [a for a in alarms if a["t"] >= 52.0 and all(a is not e for e in resized[:1])]
            second += bool(late) and late[0]["kind"] == then
            other += _others(alarms, alarms[0] if alarms else None, *resized[:1], *late[:1])
        unit = " %" if truth > 0 else " N"
        size = f"{min(sizes):.3g} to {max(sizes):.3g}{unit}" if sizes else "-"
        when = f"{np.median(times):.2f}" if times else "-"
        print(f"| {label} | {len(seeds)} | {said} | {when} | {size} | {inside} | {ends} | "
              f"{second} | {other} |")  # fmt: skip
    print(f"total {time.perf_counter() - t0:.0f} s")


#: second: the first changes, from 20 s, and the ballast changes (N) from 35 s after them
FIRSTS = {
    "snag -10 N + 1 N m yaw": Fault("external", 20.0, force=SNAG),
    "h1 stopped": Fault("thruster", 20.0, thruster="h1", efficiency=0.0),
}
BALLASTS = (7.0, 8.0, 9.0, 10.0)
SECOND_T = 35.0
#: second: the single changes from 20 s, watched for an alarm after the first
SINGLES = {
    "h1 stopped": FIRSTS["h1 stopped"],
    "v2 stopped": Fault("thruster", 20.0, thruster="v2", efficiency=0.0),
    "h3 at 30 %": Fault("thruster", 20.0, thruster="h3", efficiency=0.3),
    "v4 at 30 %": Fault("thruster", 20.0, thruster="v4", efficiency=0.3),
    "snag -10 N + 1 N m yaw": FIRSTS["snag -10 N + 1 N m yaw"],
    **{k: OTHERS[k] for k in ("snag -8 N + 1.5 N m yaw", "tether pull -15 N surge",
                              "side push 10 N sway", "payload 10 N heavy", "float 6 N light",
                              "payload 2 kg, 4 N lift (W-B +15.6 N)",
                              "payload 3 kg, 25 N lift (W-B +4.4 N)")},
}  # fmt: skip


def _span(values: list[float]) -> str:
    """The range of ``values`` as a table cell ("-": none measured)."""
    return f"{min(values):.2f}-{max(values):.2f}" if values else "-"


def second(
    monitor: ResidualMonitor | None = None,
    seeds: range | list[int] = range(1, 9),
    single_seeds: range | list[int] = range(1, 8),
    firsts: dict[str, Fault] | None = None,
    ballasts: tuple[float, ...] = BALLASTS,
    singles: dict[str, Fault] | None = None,
    run_s: float = 60.0,
    single_s: float = 90.0,
) -> None:
    """A ballast change from 35 s after a first change (:data:`FIRSTS` × :data:`BALLASTS`): is
    it isolated, when, at what size, with what other alarms? And single changes
    (:data:`SINGLES`): alarms after the first, and the highest reading over the DOF
    equations the change leaves alone among the alarms dismissed
    (:attr:`~nnid.fault.detect.DetectResult.dismissed`), with the level it was judged against.
    ``monitor`` (default: the scenarios monitor) and the rest: a smaller run (tests)."""
    vehicle = load_vehicle(VEHICLE)
    t0 = time.perf_counter()
    mon = monitor if monitor is not None else trained(vehicle)
    firsts = FIRSTS if firsts is None else firsts
    singles = SINGLES if singles is None else singles
    print(f"machine: {machine(numba=numba.__version__)}; date {datetime.date.today()}")
    print(f"| first change, from 20 s ({run_s:g}-s runs) | ballast from {SECOND_T:g} s | runs | "
          "first alarmed | ballast isolated | time (median, latest; s) | size said (N) | "
          "other alarms |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    for label, first in firsts.items():
        for value in ballasts:
            ballast = Fault("effect", SECOND_T, effect="buoyancy_offset", value=value)
            alarmed, times, sizes, other = 0, [], [], 0
            for seed in seeds:
                log = simulate_faults(vehicle, run_s, faults=[first, ballast], seed=seed)
                alarms = detect(mon, log).alarms
                head = next((a for a in alarms if first.t <= a["t"] < SECOND_T), None)
                iso = next((a for a in alarms if a["t"] >= SECOND_T
                            and a.get("hypothesis") == "buoyancy_offset"), None)  # fmt: skip
                alarmed += head is not None
                if iso is not None:
                    times.append(iso["t"])
                    sizes.append(iso["value"])
                other += _others(alarms, head, iso)
            when = f"{np.median(times):.2f}, {max(times):.2f}" if times else "-"
            print(f"| {label} | {value:g} N | {len(seeds)} | {alarmed} | {len(times)} | {when} | "
                  f"{_span(sizes)} | {other} |")  # fmt: skip
    print()
    print(f"| single change, from 20 s ({single_s:g}-s runs) | runs | first alarm at the change "
          "| alarms after the first | alarms dismissed | highest beside-reading | level it was "
          "judged against |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for label, fault in singles.items():
        at, later, dismissed, top = 0, 0, 0, None
        for seed in single_seeds:
            result = detect(mon, simulate_faults(vehicle, single_s, faults=[fault], seed=seed))
            alarms = result.alarms
            at += bool(alarms) and alarms[0]["t"] >= fault.t
            later += max(len(alarms) - 1, 0)
            dismissed += len(result.dismissed)
            read = [d for d in result.dismissed if d["beside_ratio"] is not None]
            best = max(read, key=lambda d: d["beside_ratio"], default=None)
            if best is not None and (top is None or best["beside_ratio"] > top["beside_ratio"]):
                top = best
        reading, level = (
            ("-", "-")
            if top is None
            else (f"{top['beside_ratio']:.2f}", f"{top['beside_allowed']:.2f}")
        )
        print(f"| {label} | {len(single_seeds)} | {at} | {later} | {dismissed} | {reading} | "
              f"{level} |")  # fmt: skip
    print(f"total {time.perf_counter() - t0:.0f} s")


#: the changes of the follow mode, isolated at 20 s of 10-minute streams
FOLLOWED = {
    "h1 at 30 %": Fault("thruster", 20.0, thruster="h1", efficiency=0.3),
    "snag -10 N + 1 N m yaw": Fault("external", 20.0, force=SNAG),
    "10 N ballast": Fault("effect", 20.0, effect="buoyancy_offset", value=10.0),
}


def _followed(mon, path: str) -> dict:
    """``path`` followed, each row's reading timed (from the row read to the next read), the
    rows after which a signature was taken out (a flush) marked, with that call's rows."""
    stamps, flushed, sizes = [], [], []
    read, left = follow_module._rows, Rewatch.left

    def rows(source, idle_s, *rest):  # rest: the dialect found, which follow_csv reads back
        for row in read(source, idle_s, *rest):
            stamps.append(time.perf_counter())
            flushed.append(False)
            yield row
        stamps.append(time.perf_counter())
        flushed.append(False)  # the flushes after the last row (the run's end) are not timed

    def timed_left(self, data, rows_, r, to_end=False):
        flushed[-1] = True
        sizes.append(rows_.size)
        return left(self, data, rows_, r, to_end)

    follow_module._rows, Rewatch.left = rows, timed_left
    try:
        result = follow_module.follow_csv(mon, path, 10.0, lambda line: None, idle_s=0.0)
    finally:
        follow_module._rows, Rewatch.left = read, left
    cost = np.diff(stamps)[1:]  # each data row's reading (the header's first)
    at = np.flatnonzero(flushed[1:-1])
    quarter, rows_quarter = max(at.size // 4, 1), cost.size // 4
    return {
        "alarms": [[round(a["t"], 2), a["kind"]] for a in result.alarms],  # as JSON has them
        "flushes": int(at.size),
        "first_ms": 1e3 * float(np.median(cost[at[:quarter]])),
        "last_ms": 1e3 * float(np.median(cost[at[-quarter:]])),
        "rows_median": int(np.median(sizes)) if sizes else 0,
        "rows_max": max(sizes, default=0),
        "row_first_us": 1e6 * float(np.median(cost[:rows_quarter])),
        "row_last_us": 1e6 * float(np.median(cost[-rows_quarter:])),
        "row_us": 1e6 * float(np.mean(cost)),
    }


def follow_streams() -> dict:
    """Each change of :data:`FOLLOWED` followed on a 10-minute stream (after one short stream
    that compiles the kernels)."""
    vehicle = load_vehicle(VEHICLE)
    mon = trained(vehicle)
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        warm = simulate_faults(vehicle, 40, faults=[FOLLOWED["h1 at 30 %"]], seed=31)
        warm.to_csv(f"{tmp}/warm.csv", index=False)
        _followed(mon, f"{tmp}/warm.csv")
        for i, (label, fault) in enumerate(FOLLOWED.items()):
            log = simulate_faults(vehicle, 600, faults=[fault], seed=41 + i)
            log.to_csv(f"{tmp}/{i}.csv", index=False)
            out[label] = _followed(mon, f"{tmp}/{i}.csv")
    return out


def follow() -> None:
    """``detect --follow``'s cost per flush after an isolated change (the module docstring);
    ``sys.argv[2]``, where given, the revision it is compared with."""
    rev = sys.argv[2] if len(sys.argv) > 2 else None
    if rev == "--json":  # a subprocess of another tree's run: its numbers only
        print(json.dumps(follow_streams()))
        return
    t0 = time.perf_counter()
    here = follow_streams()
    before = _at_revision(rev) if rev else None
    print(f"machine: {machine(numba=numba.__version__)}; date {datetime.date.today()}")
    print("| change at 20 s, 600-s stream | alarms | flushes | rows per signature (median, "
          "max) | per flush, first / last quarter (ms) | growth (last / first) | per row, "
          "median of the first / last quarter (us) | per row, mean (us) |"
          + (f" per flush at {rev} (ms) | {rev} / this tree |" if rev else ""))  # fmt: skip
    print("|---|---|---|---|---|---|---|---|" + ("---|---|" if rev else ""))
    for label, h in here.items():
        line = (f"| {label} | {len(h['alarms'])} | {h['flushes']} | {h['rows_median']}, "
                f"{h['rows_max']} | {h['first_ms']:.2f} / {h['last_ms']:.2f} | "
                f"{h['last_ms'] / h['first_ms']:.2f} | {h['row_first_us']:.0f} / "
                f"{h['row_last_us']:.0f} | {h['row_us']:.0f} |")  # fmt: skip
        if before is not None:
            b = before[label]
            same = "" if b["alarms"] == h["alarms"] else " (other alarms!)"
            mine, theirs = h["first_ms"] + h["last_ms"], b["first_ms"] + b["last_ms"]
            line += (f" {b['first_ms']:.2f} / {b['last_ms']:.2f}{same} | "
                     f"{theirs / mine:.1f}x |")  # fmt: skip
        print(line)
    print(f"total {time.perf_counter() - t0:.0f} s")


def _at_revision(rev: str) -> dict:
    """:func:`follow_streams` with the nnid of git revision ``rev`` (this script run on it in a
    subprocess, that revision's package first on its path)."""
    return at_revision(rev, Path(__file__), "follow", "--json")


MODES = {
    "speed": speed,
    "scenarios": scenarios,
    "ended": ended,
    "second": second,
    "follow": follow,
}


def parser() -> argparse.ArgumentParser:
    """The command line: a mode (the module docstring says what each measures) and, for
    ``follow``, the revision it is compared with."""
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("mode", nargs="?", default="speed", choices=list(MODES),
                    help="what to measure (default: speed)")  # fmt: skip
    ap.add_argument("rev", nargs="?", help="follow only: a git revision to compare with")
    # follow's subprocess on another revision's tree prints its numbers as JSON (follow reads
    # sys.argv itself): not for a person
    ap.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    return ap


if __name__ == "__main__":
    ap = parser()
    args = ap.parse_args()
    if (args.rev or args.json) and args.mode != "follow":
        ap.error(f"{args.mode} takes no revision: only follow compares with one")
    MODES[args.mode]()
