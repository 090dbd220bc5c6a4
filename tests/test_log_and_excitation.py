"""The log validator, excitation signals, the autopilot and divergence reporting."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pandas as pd
import pytest

from nnid.datasets.excitation import (
    APRBS,
    PRBS,
    Chirp,
    DOptimalSine,
    Multisine,
    Stairs,
    Step,
    WeissSequence,
    doptimal_frequency,
    mls,
)
from nnid.datasets.log import ANGLES, validate_log
from nnid.datasets.readers import read_log
from nnid.datasets.simulator import Autopilot, simulate
from nnid.errors import NnidInputError
from nnid.vehicle import load_vehicle


def _log(n=20):
    t = np.arange(n) * 0.1
    return pd.DataFrame({"t": t, "u": np.sin(t), "psi": 0.1 * t, "tau_X": np.ones(n)})


def test_valid_log_passes_untouched():
    df = _log()
    assert validate_log(df, "a.csv") is df


def test_a_contract_column_misspelt_is_refused_or_said():
    """'W' for w was kept as an unknown column while w was derived from depth. Longer names
    and names with spaces are refused; a single letter that differs only in case is said and
    the log kept (P may be a pressure, V a battery voltage)."""
    for wrong, meant in (("Experiment", "experiment"), ("tau_x", "tau_X"), (" u", "u")):
        df = _log().rename(columns={"u": "w"} if meant == "u" else {})
        df = df.rename(columns={"tau_X": wrong} if meant == "tau_X" else {})
        df[wrong] = df.get(wrong, "run")
        with pytest.raises(NnidInputError, match=f"did you mean '{meant}'") as err:
            validate_log(df, "a.csv")
        assert err.value.field == wrong
    with pytest.warns(UserWarning, match="'P' is not a column of the log contract.*'p'"):
        pressure = _log().assign(P=1.0e5)
        assert validate_log(pressure, "a.csv") is pressure and "P" in pressure
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # p itself logged: P is something else, nothing to say
        validate_log(_log().assign(p=0.0, P=1.0e5), "a.csv")


def _set(column: str, row: int, value):
    return lambda d: d.assign(**{column: d[column].where(d.index != row, value)})


@pytest.mark.parametrize(
    "mutate, column, row, words",
    [
        (lambda d: d.drop(columns="t"), None, None, "'t'"),
        (lambda d: d.drop(columns=["u", "psi"]), None, None, "no motion columns"),
        (lambda d: d.drop(columns="tau_X"), None, None, "no input columns"),
        (lambda d: d.assign(t=d["t"].where(d.index != 7, d["t"][6])), "t", 7, "duplicated"),
        (lambda d: d.assign(t=d["t"].where(d.index != 9, 0.05)), "t", 9, "decreasing"),
        # an empty input cell is refused; an empty motion cell is a gap (tests/test_gaps.py)
        (_set("tau_X", 4, np.nan), "tau_X", 4, "empty (NaN) is not"),
        (lambda d: d.assign(u=d["u"].where(d.index != 5, -np.inf)), "u", 5, "-inf is"),
        (lambda d: d.assign(tau_X=d["tau_X"].where(d.index != 3, np.inf)), "tau_X", 3, "inf is"),
        (lambda d: d.assign(psi=d["psi"] * 180), "psi", 19, "degrees"),
        # beyond any vehicle: a unit slip (mm/s) or a corrupt sample, not data to fit
        (lambda d: d.assign(u=d["u"] * 1000), "u", 16, "m/s is not a speed"),
        (_set("tau_X", 8, 1e300), "tau_X", 8, "N is not a force"),
        (lambda d: d.assign(experiment=["a"] * 19 + ["b"]), "experiment", 19, "single sample"),
    ],
)
def test_bad_logs_name_file_column_row(mutate, column, row, words):
    with pytest.raises(NnidInputError) as info:
        validate_log(mutate(_log()), "run7.csv")
    msg = str(info.value)
    assert "run7.csv" in msg and words in msg and "np." not in msg  # numbers, not type names
    if column:
        assert f"column '{column}'" in msg and f"row {row}" in msg


def test_integer_milliseconds_at_250_hz_to_1_khz_are_refused():
    """Milliseconds step by 1 to 4 at 250 Hz to 1 kHz, under the rule's 5: a 1-kHz log was
    read as seconds, 60 s became 17 h, without a word. Integer steps are refused as
    milliseconds; a log in seconds that steps by about a second with fractions passes, and a
    step of exactly 1000 is microseconds (1 kHz) rather than a whole-second 1-Hz log."""
    rng = np.random.default_rng(3)
    n = 400
    for steps in (np.full(n - 1, 1.0), np.full(n - 1, 4.0), rng.integers(3, 6, n - 1) * 1.0):
        t = 1.7e12 + np.r_[0.0, np.cumsum(steps)]  # Unix milliseconds
        with pytest.raises(NnidInputError, match="whole number: this looks like milliseconds"):
            validate_log(_log(n).assign(t=t), "imu.csv")
        with pytest.raises(NnidInputError, match="milliseconds") as err:
            validate_log(_log(n).assign(t=t - t[0]), "imu.csv")
        assert err.value.field == "t" and "imu.csv" in str(err.value)
    # seconds at ~1 Hz as a ROS clock stamps them, and at 250 Hz: not milliseconds
    ros = 1.7e9 + np.arange(n) + rng.uniform(0, 0.02, n)
    validate_log(_log(n).assign(t=ros), "slow.csv")
    validate_log(_log(n).assign(t=np.arange(n) * 0.004), "fast.csv")
    with pytest.raises(NnidInputError, match=r"by 1000 \(median\): this looks like micro"):
        validate_log(_log(n).assign(t=np.arange(n) * 1000.0), "imu.csv")
    jittered = np.arange(n) * 1000.0 + rng.integers(-2, 3, n)  # a 1-Hz logger's milliseconds
    with pytest.raises(NnidInputError, match="like milliseconds"):
        validate_log(_log(n).assign(t=jittered), "imu.csv")
    # two runs, each its own clock: the jump between them is no sample step (it made the
    # 1-kHz log in microseconds read as milliseconds, and a log in seconds fail the rule)
    two = _log(n).assign(t=np.r_[np.arange(n // 2), np.arange(n - n // 2) + 7.5] * 1000.0,
                         experiment=["a"] * (n // 2) + ["b"] * (n - n // 2))  # fmt: skip
    with pytest.raises(NnidInputError, match=r"by 1000 \(median\): this looks like micro"):
        validate_log(two, "imu.csv")


def test_unwrapped_radians_past_two_pi_are_told_from_degrees_by_the_rate():
    """A yaw past 2π after whole turns (a filter's, or nnid's own simulator with no
    measurement model) was refused as degrees; the yaw rate r tells the two apart."""
    t = np.arange(400) * 0.1
    turns = pd.DataFrame({"t": t, "psi": 0.5 * t, "r": np.full(t.size, 0.5), "tau_N": 1.0})
    assert validate_log(turns, "turns.csv") is turns  # 20 rad, turning at the logged 0.5 rad/s
    with pytest.raises(NnidInputError, match="'psi', row 399: angle of 1143 looks like degrees"):
        validate_log(turns.assign(psi=np.degrees(turns["psi"])), "turns.csv")
    # without r nothing tells them apart: refused, saying what would
    with pytest.raises(NnidInputError, match="read where the log also has the angle's rate"):
        validate_log(turns.drop(columns="r"), "turns.csv")
    degrees = np.degrees(turns["psi"])
    for name, wrong in (
        # a compass held between its 1-Hz updates: no change between most samples
        ("held", turns.assign(psi=degrees.groupby(np.arange(t.size) // 10).transform("first"))),
        # the rate in deg/s too: the angle keeps pace with it, but no ROV turns at 29 rad/s
        ("both in degrees", turns.assign(psi=degrees, r=np.degrees(turns["r"]))),
    ):
        with pytest.raises(NnidInputError, match="looks like degrees"):
            validate_log(wrong, f"{name}.csv")


def test_a_small_pitch_in_degrees_is_refused():
    """The zyx pitch stays within ±π/2: a pitch of up to 4° logged in degrees passed as 4 rad
    (229°) because only values past 2π were taken for degrees."""
    t = np.arange(400) * 0.1
    pitch = 0.07 * np.sin(0.5 * t)  # rad, 4° at most
    log = pd.DataFrame({"t": t, "theta": pitch, "q": np.gradient(pitch, t), "tau_M": 1.0})
    assert validate_log(log, "pitch.csv") is log
    steep = log.assign(theta=pitch + 1.45)  # 87°: radians
    assert validate_log(steep, "pitch.csv") is steep
    said = r"'theta', row 157: angle of 4\.011 looks like degrees.*within ±π/2"
    degrees = log.assign(theta=np.degrees(pitch))
    with pytest.raises(NnidInputError, match=said):  # told by the rate q
        validate_log(degrees, "pitch.csv")
    # without q a pitch within ±2π is read as radians: nnid's own simulator flies a pose-only
    # log's pitch through ±π (Seamor's surge-heave run), and nothing tells that from degrees
    no_rate = degrees.drop(columns="q")
    assert validate_log(no_rate, "pitch.csv") is no_rate


def test_time_restarts_per_experiment_are_fine(tmp_path):
    a, b = _log(), _log()
    a["experiment"], b["experiment"] = "a", "b"
    both = pd.concat([a, b], ignore_index=True)
    both.to_csv(tmp_path / "x.csv", index=False)
    assert len(read_log(tmp_path / "x.csv")) == 40
    (tmp_path / "y.txt").write_text("t,u\n")
    with pytest.raises(NnidInputError, match="unknown log format"):
        read_log(tmp_path / "y.txt")
    (tmp_path / "z.parquet").write_bytes(b"PAR1 truncated")
    with pytest.raises(NnidInputError, match="cannot be read"):
        read_log(tmp_path / "z.parquet")


def test_prbs_is_maximum_length():
    """An MLS of order n has period 2ⁿ − 1, one more +1 than −1, and a two-valued
    circular autocorrelation (N at lag 0, −1 elsewhere)."""
    for order in (5, 7, 9):
        s = mls(order)
        n = 2**order - 1
        assert s.size == n and s.sum() == 1
        acf = [np.dot(s, np.roll(s, k)) for k in range(n)]
        assert acf[0] == n and set(acf[1:]) == {-1}
    sig = PRBS(channel="X", amplitude=2.0, hold=0.5, duration=10.0, offset=1.0)
    x = sig(np.arange(0, 12, 0.01))
    assert set(np.unique(x[:1000])) == {-1.0, 3.0} and (x[1000:] == 0).all()


def test_aprbs_levels_and_holds_cover_the_range():
    """APRBS: each level held between hold_min and hold_max, levels spread over offset ±
    amplitude (not two values, as PRBS), the same draw for the same seed, zero after the run."""
    sig = APRBS(channel="X", amplitude=30.0, hold_min=2.0, hold_max=8.0, duration=400.0, offset=5.0)
    t = np.arange(0, 410, 0.01)
    x = sig(t)
    on = t < 400.0
    assert (x[~on] == 0).all()
    assert (x[on] >= -25.0).all() and (x[on] <= 35.0).all()
    change = np.flatnonzero(np.diff(x[on]) != 0) + 1
    holds = np.diff(t[change])
    assert holds.min() >= 2.0 - 0.011 and holds.max() <= 8.0 + 0.011
    assert 400 / 8.0 <= change.size + 1 <= 400 / 2.0 + 1
    levels = x[on][np.r_[0, change]]
    assert np.unique(levels).size == levels.size  # amplitude-modulated: no repeated level
    assert np.histogram(levels, bins=4, range=(-25.0, 35.0))[0].min() >= 5  # whole range seen
    assert np.array_equal(x, APRBS(**sig.model_dump())(t))
    assert not np.array_equal(x, APRBS(**{**sig.model_dump(), "seed": 1})(t))
    with pytest.raises(ValueError, match="hold_max must be at least hold_min"):
        APRBS(channel="X", amplitude=1.0, hold_min=3.0, hold_max=2.0, duration=10.0)


def test_multisine_peak_and_spectrum():
    sig = Multisine(channel="Y", amplitude=3.0, f_min=0.1, f_max=1.0, n=10, duration=100.0)
    t = np.arange(0, 100, 0.01)
    x = sig(t)
    assert abs(np.abs(x).max() - 3.0) < 0.01
    spec = np.abs(np.fft.rfft(x))
    freqs = np.fft.rfftfreq(t.size, 0.01)
    lines = freqs[np.argsort(spec)[-10:]]
    assert np.allclose(np.sort(lines), np.linspace(0.1, 1.0, 10), atol=0.011)


def test_steps_stairs_chirp():
    t = np.arange(0, 10, 0.01)
    assert Step(channel="X", amplitude=2.0, start=1.0, duration=2.0)(t)[
        [50, 150, 350]
    ].tolist() == [0, 2, 0]
    stairs = Stairs(channel="X", levels=[1.0, -2.0, 3.0], hold=2.0)(t)
    assert stairs[[100, 300, 500, 700]].tolist() == [1.0, -2.0, 3.0, 0.0]
    chirp = Chirp(channel="N", amplitude=1.0, f0=0.5, f1=2.0, duration=10.0)(t)
    crossings = t[np.flatnonzero(np.diff(np.sign(chirp)) != 0)]
    # half a period between zero crossings at the instantaneous f(t) = f0 + (f1 - f0) t / T
    mid, half = 0.5 * (crossings[1:] + crossings[:-1]), np.diff(crossings)
    assert np.allclose(1.0 / (2.0 * half), 0.5 + 1.5 * mid / 10.0, rtol=0.03)


def test_doptimal_frequency_reproduces_caccia():
    """Caccia eqs 13-14 on ROMEO: yaw (linear, k_r = 28.6, prior I = 93.75) ω = 0.176 rad/s;
    surge (675 kg prior, k = 46.9, k₂ = 306.2, φ̂ = 35 N so ξ* ≈ 0.27 m/s) ω ≈ 0.18 rad/s."""
    assert doptimal_frequency(93.75, 28.6, 0.0, -5.0) == pytest.approx(0.176, abs=1e-3)
    assert doptimal_frequency(675.0, 46.9, 306.2, 35.0) == pytest.approx(0.1815, abs=1e-3)
    sig = DOptimalSine(channel="X", offset=35.0, amplitude=25.0, inertia=675.0, k_linear=46.9,
                       k_quadratic=306.2, duration=100.0)  # fmt: skip
    x = sig(np.arange(0, 100, 0.1))
    assert x.min() > 0  # never reverses thrust
    with pytest.raises(ValueError):
        DOptimalSine(
            channel="X", offset=10.0, amplitude=25.0, inertia=1.0, k_linear=1.0, duration=1.0
        )


def test_weiss_sequence_order_and_non_collinear_coupled_runs():
    seq = WeissSequence().experiments()
    names = [e["name"] for e in seq]
    assert names[:5] == ["surge", "sway", "heave", "roll", "yaw"]
    assert names[5:] == ["surge-sway", "surge-heave", "surge-yaw", "sway-heave", "sway-yaw",
                         "heave-yaw", "surge-sway-heave", "surge-sway-yaw"]  # fmt: skip
    run = next(e for e in seq if e["name"] == "surge-sway-heave")
    t = np.arange(0, run["duration"], 0.01)
    x = np.stack([Stairs(**s)(t) for s in run["signals"]], 1)
    assert np.linalg.matrix_rank(x) == 3 and np.linalg.cond(x) < 20


def test_weiss_coupled_runs_fly_the_levels_their_docstring_says():
    """The second and third DOF of a coupled run switch on slower clocks and, in the same run
    length, fly only the first three and two levels, positive only (kept as flown: the Seamor
    configs' data come from it; the docstring said both signs were seen)."""
    runs = {e["name"]: e for e in WeissSequence().experiments()}
    x, y = runs["surge-sway"]["signals"]
    assert x["levels"] == [9.0, 19.5, 30.0, -15.0, -30.0] and y["levels"] == [9.0, 19.5, 30.0]
    assert runs["surge-sway-yaw"]["signals"][2]["levels"] == [1.2, 2.6]
    assert "first three (0.3, 0.65, 1" in WeissSequence.__doc__


def test_prbs_chips_and_stairs_levels_fall_on_the_sample_clock():
    """t = k dt is inexact and floor((k dt)/hold) read a sample just under a chip's edge as
    the chip before: a PRBS at hold = dt = 0.01 repeated 54 chips and skipped 54 in 1000
    samples (no longer an MLS's autocorrelation), stairs of 0.07 s at dt 0.01 held levels of
    6 to 8 samples. Read with the simulator's slack, each chip and level is its own samples."""
    t = np.arange(1000) * 0.01
    assert np.array_equal(PRBS(channel="X", amplitude=1.0, hold=0.01, duration=10.0,
                               order=10)(t), mls(10)[:1000])  # fmt: skip
    x = PRBS(channel="X", amplitude=1.0, hold=0.01, duration=1.27, order=7)(t[:127])
    acf = [np.dot(x, np.roll(x, k)) for k in range(127)]
    assert acf[0] == 127 and set(acf[1:]) == {-1}
    stairs = Stairs(channel="X", levels=list(range(1, 13)), hold=0.07, start=0.03)(t[:100])
    assert np.bincount(stairs.astype(int)).tolist() == [16] + [7] * 12


@pytest.mark.parametrize(
    ("dt", "start", "duration"),
    [(0.1, 1.1, 3.2),  # 1.1 + 3.2 = 4.300000000000001 > 43 * 0.1: a 33rd sample flown
     (0.3, 0.9, 0.6)],  # 3 * 0.3 = 0.8999999999999999 < 0.9: the start a sample late
)  # fmt: skip
def test_signal_windows_fall_on_the_sample_clock(dt, start, duration):
    """A signal's window was read as t >= start and t < start + duration, with t = k·dt and
    the edges inexact: a sample within rounding of an edge fell on either side. Read as the
    chips are, a window starts at sample start/dt and lasts duration/dt samples."""
    t = np.arange(100) * dt
    first, n = round(start / dt), round(duration / dt)
    for signal in (
        Step(channel="X", amplitude=1.0, start=start, duration=duration),
        PRBS(channel="X", amplitude=1.0, hold=dt, start=start, duration=duration),
    ):
        on = np.flatnonzero(signal(t))
        assert (on[0], on.size) == (first, n), signal
    held = np.flatnonzero(Step(channel="X", amplitude=1.0, start=start)(t))  # no end
    assert (held[0], held.size) == (first, t.size - first)


def test_a_multisine_of_one_frequency_is_refused_naming_its_keys():
    """n > 1 sines of one frequency with Schroeder phases are one sine, and for an even n
    cancel to a peak of ~5e-15, which the amplitude then divided: rounding noise flown at
    full amplitude, broadband. And n = 1 flies f_min alone while Nyquist is checked on f_max."""
    keys = dict(channel="X", amplitude=1.0, duration=10.0)
    with pytest.raises(ValueError, match=r"f_min = f_max = 0\.5 Hz with n = 8"):
        Multisine(**keys, f_min=0.5, f_max=0.5)
    with pytest.raises(ValueError, match=r"n = 1 flies one sine at f_min = 0\.5 Hz, not f_max"):
        Multisine(**keys, f_min=0.5, f_max=2.0, n=1)
    one = Multisine(**keys, f_min=0.5, f_max=0.5, n=1)(np.arange(0, 10, 0.01))
    assert abs(np.abs(one).max() - 1.0) < 1e-3


def test_random_signals_that_draw_the_same_sequence_are_warned_of():
    """Two PRBS (or APRBS) of one experiment left on their default seeds fly the same
    sequence: collinear inputs that no regression separates, and --seed moves only the noise.
    Said naming the experiment and channels; a signal of its own seed is not."""
    from nnid.config import SimulateConfig
    from nnid.datasets.simulator import simulate_config
    from nnid.errors import ExcitationWarning

    prbs = {"kind": "prbs", "amplitude": 5.0, "hold": 0.2, "duration": 1.0}
    aprbs = {"kind": "aprbs", "amplitude": 5.0, "hold_min": 0.2, "hold_max": 0.4,
             "duration": 1.0}  # fmt: skip
    runs = [
        {"name": "same", "signals": [prbs | {"channel": "X"}, prbs | {"channel": "Y"},
                                     aprbs | {"channel": "Z"}, aprbs | {"channel": "N"}]},
        # a PRBS seed is its register's start state modulo the period (2^7 - 1)
        {"name": "period", "signals": [prbs | {"channel": "X"},
                                       prbs | {"channel": "N", "seed": 128}]},
        {"name": "own", "signals": [prbs | {"channel": "X"}, prbs | {"channel": "Y", "seed": 2},
                                    aprbs | {"channel": "Z"},
                                    aprbs | {"channel": "N", "seed": 3}]},
    ]  # fmt: skip
    cfg = SimulateConfig(vehicle="seamor", dt=0.1, experiments=runs)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        simulate_config(cfg, load_vehicle("seamor"))
    said = [str(w.message) for w in caught if w.category is ExcitationWarning]
    assert len(said) == 3, said
    assert said[0].startswith("experiment 'same': the prbs signals on X, Y draw the same")
    assert said[1].startswith("experiment 'same': the aprbs signals on Z, N draw the same")
    assert said[2].startswith("experiment 'period': the prbs signals on X, N")
    assert "(seed 1, the same holds)" in said[0]  # one seed shared: said once
    assert "(seeds 1 on X, 128 on N, the same holds)" in said[2]  # each its own, said each
    assert "--seed move the sensor noise only" in said[0]


def test_thruster_commands_beyond_their_range_are_said_with_their_share():
    """Commands beyond a thruster's range are flown at its bound (a PRBS of ±1.5 on a ±1
    thruster flew ±1 throughout, logged ±1.5) without a word unless far beyond; a thruster
    with only cmd_max was clipped with none at all. Said per thruster, with the share."""
    from nnid.datasets.arrays import CommandSaturationWarning

    veh = load_vehicle("vlbv300")  # PWM range ±102 on every thruster
    one_sided = veh.thrusters[1].model_copy(update={"cmd_min": None})
    veh = veh.model_copy(update={"thrusters": [veh.thrusters[0], one_sided, *veh.thrusters[2:]]})
    inputs = np.zeros((10, len(veh.thrusters)))
    inputs[:5, 0] = 150.0
    inputs[:2, 1] = 120.0
    inputs[:, 1] -= 500.0 * (np.arange(10) == 9)  # below -102, but no cmd_min: flown as asked
    with pytest.warns(CommandSaturationWarning) as said:
        simulate(veh, inputs, 0.1, experiment="pwm")
    message = str(said[0].message)
    names = [t.name for t in veh.thrusters]
    assert message.startswith("experiment 'pwm': thruster commands beyond the thruster's range")
    assert f"{names[0]} in 50% of the samples (asked 0 to 150, flown within [-102, 102])" in message
    assert f"{names[1]} in 20% of the samples (asked -500 to 120, flown at most 102)" in message
    with warnings.catch_warnings():
        warnings.simplefilter("error", CommandSaturationWarning)
        simulate(veh, np.clip(inputs, -102.0, 102.0), 0.1)


def test_a_failed_adaptive_solve_is_the_diverged_simulation_error():
    """The adaptive integrator's failure was a bare RuntimeError, a traceback from the CLI;
    it is the fixed-step integrators' NnidInputError, naming the time and the experiment."""
    from nnid.vehicle import Vehicle

    veh = Vehicle.model_validate({
        "name": "box", "mass": 30.0, "inertia": [1.0, 2.0, 2.0],
        "damping": {"model": "weiss_quadratic", "coefficients": {"X:u*abs(u)": 40.0}},
    })  # fmt: skip
    inputs = np.zeros((41, 6))
    inputs[:, 0] = 100.0
    with pytest.raises(NnidInputError, match=r"diverged at t = \d.* in experiment 'run'") as err:
        simulate(veh, inputs, 0.05, integrator="adaptive", experiment="run")
    assert err.value.field == "experiments"


def test_autopilot_holds_an_unstable_vehicle_and_logs_its_force():
    """The bare VT 690 hull with McFarland damping diverges in open loop (M:q*abs(u) > 0);
    under a PD autopilot it cruises, and the log carries the commanded feedback."""
    veh = load_vehicle("vt690")
    inputs = np.tile([11.0, 0, 0, 0, 0, 0], (600, 1))
    x0 = [0, 0, 2, 0, 0, 0, 1.5, 0, 0, 0, 0, 0]
    with pytest.raises(NnidInputError, match="diverged at t = "):
        simulate(veh, inputs, 0.05, x0=x0, substeps=5)
    ap = Autopilot(
        kp=[0, 0, 40, 5, 60, 30], kd=[0, 0, 60, 1.5, 80, 80], reference=[0, 0, 2, 0, 0, 0]
    )
    log = simulate(veh, inputs, 0.05, x0=x0, substeps=5, autopilot=ap)
    assert np.abs(log["theta"]).max() < 0.1 and abs(log["z"].iloc[-1] - 2.0) < 0.05
    assert log["u"].iloc[-1] == pytest.approx(1.5, abs=0.1)
    assert np.abs(log["tau_M"]).max() > 0  # feedback is in the logged input
    assert math.isclose(log["tau_X"].iloc[0], 11.0)


@pytest.mark.parametrize("integrator", ["rk4", "torch"])
def test_an_autopilot_holds_a_point_whatever_the_heading(integrator):
    """x/y gains act on the north/east error; surge and sway are body forces. The push went
    into them unturned, so facing south (ψ = π) it drove the vehicle away from the point it
    held. Both flights (the compiled RK4 and the per-sample law) turn it by the heading."""
    veh = load_vehicle("seamor")
    pilot = Autopilot(
        kp=[20, 20, 20, 0, 0, 5], kd=[40, 40, 40, 0, 0, 5], reference=[0, 0, 0, 0, 0, math.pi]
    )
    x0 = [1.0, -1.0, 0, 0, 0, math.pi - 0.2, 0, 0, 0, 0, 0, 0]
    log = simulate(veh, np.zeros((1200, 6)), 0.05, x0=x0, autopilot=pilot, integrator=integrator)
    assert np.hypot(log["x"].iloc[-1], log["y"].iloc[-1]) < 0.05, log[["x", "y"]].iloc[-1]


def _turning_log(rates, seconds=60.0, dt=0.05, seed=0):
    """A log whose attitude turns with the body rates ``rates(t) -> [N, 3]`` (rad/s), integrated
    on the rotation (so a pitch through ±π/2 is met as a sensor writes it, φ and ψ jumping by
    π), sampled at ``dt`` with 2 mrad of attitude noise and 5 mrad/s of gyro noise."""
    from scipy.spatial.transform import Rotation

    from nnid.datasets.mapping import euler_from_rotation

    rng = np.random.default_rng(seed)
    sub = 10  # integration substeps per sample
    fine = np.arange(round(seconds / dt) * sub + 1) * (dt / sub)
    steps = Rotation.from_rotvec(rates(fine[:-1] + dt / sub / 2) * (dt / sub))
    rot = [Rotation.identity()]
    for step in steps:
        rot.append(rot[-1] * step)  # body-frame rate: R ← R exp([ω]× h)
    t = fine[::sub]
    # the noise on the rotation, as a filter's: near gimbal lock φ and ψ swing with it
    noise = Rotation.from_rotvec(rng.normal(0, 0.002, (t.size, 3)))
    angles = euler_from_rotation((Rotation.concatenate(rot[::sub]) * noise).as_matrix())
    gyro = rates(t) + rng.normal(0, 0.005, (t.size, 3))
    columns = {"t": t, "phi": angles[:, 0], "theta": angles[:, 1], "psi": angles[:, 2]}
    columns |= {"p": gyro[:, 0], "q": gyro[:, 1], "r": gyro[:, 2], "tau_N": np.ones(t.size)}
    return pd.DataFrame(columns)


def _wobble(t):
    return np.stack([0.4 * np.sin(0.7 * t), 0.3 * np.sin(0.45 * t + 1), 0.5 * np.sin(0.3 * t)], 1)


def test_body_rates_in_deg_per_s_beside_radians_are_refused():
    """p, q, r in deg/s beside an attitude in radians passed while under 100 "rad/s": a yaw
    rate of 30 deg/s read as 30 rad/s, every rotational fit off by 57.3. Each rate is compared
    with the rate the attitude turns at (T_Θ⁻¹ Θ̇), per experiment."""
    from nnid.datasets.log import rate_slopes

    a = _turning_log(_wobble).assign(experiment="a")
    b = _turning_log(_wobble, seed=1).assign(experiment="b")
    log = pd.concat([a, b], ignore_index=True)
    assert validate_log(log, "imu.csv") is log  # rad/s: passes
    assert all(0.95 < slope < 1.05 for *_, slope, _ in rate_slopes(log))
    said = r"imu\.csv, field 'r': r reads 5\d\.\d times .* looks like deg/s.* divide by 57\.2958"
    with pytest.raises(NnidInputError, match=said) as err:
        validate_log(log.assign(r=np.degrees(log["r"])), "imu.csv")
    assert err.value.field == "r" and "experiment 'a'" in str(err.value)
    # gaps (empty cells, a dropout of 3 s) are stepped over, not read as turning
    gappy = log.copy()
    gappy.loc[gappy.index % 17 == 0, "psi"] = np.nan
    gappy.loc[gappy.index % 23 == 0, "r"] = np.nan
    gappy = gappy.drop(index=range(300, 360))
    assert validate_log(gappy, "imu.csv") is gappy
    with pytest.raises(NnidInputError, match=r"field 'r'.*deg/s"):
        validate_log(gappy.assign(r=np.degrees(gappy["r"])), "imu.csv")
    # one experiment's rates in deg/s (a log joined from two loggers): refused, naming it
    slip = log.copy()
    slip.loc[slip["experiment"] == "b", "q"] *= 180 / np.pi
    with pytest.raises(NnidInputError, match=r"field 'q'.*in experiment 'b'.*deg/s"):
        validate_log(slip, "imu.csv")
    # rates that disagree with the attitude for another reason are not a unit: a diverged
    # filter's attitude (the Liu replays read 0.05-0.9), a gyro scale off by 2, a noisy gyro
    for other in (
        log.assign(p=0.5 * log["p"], q=0.05 * log["q"], r=2.0 * log["r"]),
        log.assign(r=log["r"] + np.random.default_rng(2).normal(0, 0.5, len(log))),
    ):
        assert validate_log(other, "imu.csv") is other


def test_the_rate_unit_check_skips_a_pitch_through_ninety_degrees():
    """A pitch looping through ±π/2 (nnid's simulator flies Seamor's through ±π): near gimbal
    lock φ and ψ jump by π between samples and their differences are no rate; those samples
    are left out and the rates in rad/s pass, in deg/s are refused."""
    from nnid.datasets.log import rate_slopes

    def loop(t):  # looping in pitch with a little roll: θ passes ±π/2 eight times
        return np.stack([0.05 * np.sin(0.5 * t), np.full(t.size, 0.4), np.zeros(t.size)], 1)

    log = _turning_log(loop)
    assert np.abs(np.cos(log["theta"])).min() < 0.1  # the run meets gimbal lock
    assert np.ptp(log["phi"]) > 3 and np.ptp(log["psi"]) > 3  # φ and ψ jump there
    assert validate_log(log, "loop.csv") is log
    assert all(0.9 < slope < 1.1 for *_, slope, _ in rate_slopes(log))
    with pytest.raises(NnidInputError, match=r"field 'p'.*looks like deg/s"):
        validate_log(log.assign(p=np.degrees(log["p"]), q=np.degrees(log["q"])), "loop.csv")


def test_the_rate_check_turns_the_attitude_as_the_kinematics_does():
    """rate_slopes' numpy T_Θ⁻¹ is nnid.physics.kinematics' matrix: rates made by the latter
    from a tumbling attitude (roll and pitch to 1 rad) read a slope of 1 on every axis."""
    import torch

    from nnid.datasets.log import rate_slopes
    from nnid.physics.kinematics import euler_rate_matrix_inverse

    t = np.arange(0.0, 60.0, 0.01)
    angles = np.stack(
        [np.sin(0.7 * t), 0.9 * np.sin(0.45 * t + 1.0), np.unwrap(2.0 * np.sin(0.2 * t))], 1
    )
    rates_of_angles = np.gradient(angles, t, axis=0)
    body = euler_rate_matrix_inverse(torch.as_tensor(angles)).numpy() @ rates_of_angles[:, :, None]
    wrapped = (angles + np.pi) % (2 * np.pi) - np.pi
    log = pd.DataFrame({"t": t, "phi": wrapped[:, 0], "theta": wrapped[:, 1],
                        "psi": wrapped[:, 2], "p": body[:, 0, 0], "q": body[:, 1, 0],
                        "r": body[:, 2, 0]})  # fmt: skip
    slopes = {col: slope for _, col, slope, _ in rate_slopes(log)}
    assert set(slopes) == {"p", "q", "r"}
    for col, slope in slopes.items():
        assert abs(slope - 1.0) < 0.01, (col, slope)


def _tumbling_run(name: str, seconds: float, dt: float) -> pd.DataFrame:
    """A run ``name`` of a tumbling attitude (roll and pitch to 0.6 rad) sampled at ``dt``,
    its body rates exact (nnid.physics.kinematics' T_Θ⁻¹ Θ̇ of the analytic angles)."""
    import torch

    from nnid.physics.kinematics import euler_rate_matrix_inverse

    t = np.arange(round(seconds / dt) + 1) * dt
    w = np.array([0.7, 0.45, 0.3])
    angles = np.array([0.6, 0.5, 1.5]) * np.sin(w * t[:, None] + np.array([0.0, 1.0, 2.0]))
    rates_of_angles = np.array([0.6, 0.5, 1.5]) * w * np.cos(w * t[:, None] + [0.0, 1.0, 2.0])
    body = euler_rate_matrix_inverse(torch.as_tensor(angles)).numpy() @ rates_of_angles[:, :, None]
    return pd.DataFrame({"t": t, "experiment": name, "phi": angles[:, 0], "theta": angles[:, 1],
                         "psi": angles[:, 2], "p": body[:, 0, 0], "q": body[:, 1, 0],
                         "r": body[:, 2, 0], "tau_N": np.ones(t.size)})  # fmt: skip


@pytest.mark.parametrize(
    ("runs", "slip"),
    [
        # a short 10-Hz run among 100-Hz ones: the log's step (0.01 s) made its windows 10 s
        # long and counted 0.5 s of them, under the 2 s the check asks
        ([("fast", 30.0, 0.01), ("slow", 15.0, 0.1)], "slow"),
        # a 100-Hz run among 10-Hz ones: windows of 0.1 s turned too little to count
        ([("slow1", 60.0, 0.1), ("slow2", 60.0, 0.1), ("fast", 10.0, 0.01)], "fast"),
    ],
)
def test_the_rate_unit_check_sizes_windows_by_each_runs_own_step(runs, slip):
    """A log joining runs logged at 10 Hz and at 100 Hz: each run's windows of about a second,
    and its seconds of them, come from its own median step, so the run of the minority rate
    whose r is in deg/s is refused, naming it, and its seconds are its own."""
    from nnid.datasets.log import rate_slopes

    log = pd.concat([_tumbling_run(*run) for run in runs], ignore_index=True)
    assert validate_log(log, "joined.csv") is log
    for name, _, slope, seconds in rate_slopes(log):
        length = next(s for n, s, _ in runs if n == name)
        assert abs(slope - 1.0) < 0.01 and seconds <= length, (name, slope, seconds)
    deg = log.assign(r=np.where(log["experiment"] == slip, np.degrees(log["r"]), log["r"]))
    with pytest.raises(NnidInputError, match=rf"field 'r'.*in experiment '{slip}'.*deg/s"):
        validate_log(deg, "joined.csv")


def test_the_rate_unit_check_sizes_windows_of_a_millisecond_clock_at_its_rate():
    """120 Hz stamped in whole milliseconds steps 8, 8, 9 ms: its median, 8 ms, sized the
    windows of about a second 125 steps long and said each of its steps was 8 ms, so 5 s of
    turning counted 3.8 s of windows. At the run's step (typical_step) a window is 120 steps,
    a second, and the windows cover the run less one second."""
    from nnid.datasets.log import rate_slopes

    true = np.arange(601) / 120  # 5 s
    zero = np.zeros(true.size)
    log = pd.DataFrame({"t": np.round(true * 1e3) / 1e3, "phi": zero, "theta": zero,
                        "psi": 0.5 * true, "p": zero, "q": zero, "r": zero + 0.5})  # fmt: skip
    ((_, col, slope, seconds),) = rate_slopes(log)
    assert col == "r" and slope == pytest.approx(1.0, rel=1e-3)
    # one step, read as the run's slope: a few 1e-7 of 1/120 off, 481 windows a few µs
    assert seconds == pytest.approx(5.0 - 1.0, abs=1 / 120 + 1e-5)


def _cruising_log(heading, seed: int = 0, experiment: str = "a") -> pd.DataFrame:
    """A minute at 10 Hz of a vehicle cruising at about 0.4 m/s with a little roll and pitch,
    its heading ``heading(t)``; x, y, z integrated from J₁(Θ) ν₁ (rotation_from_euler), the
    position noisy by 1 cm, the velocities by 1 cm/s."""
    from nnid.datasets.mapping import rotation_from_euler

    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 60.0, 0.1)
    angles = np.stack([0.1 * np.sin(0.9 * t), 0.08 * np.sin(0.6 * t + 1), heading(t)], 1)
    nu = np.stack([0.4 + 0.1 * np.sin(0.3 * t), 0.1 * np.cos(0.5 * t), 0.05 * np.sin(t)], 1)
    ned = np.einsum("nij,nj->ni", rotation_from_euler(angles), nu)
    pos = np.concatenate([[[0.0, 0.0, 1.0]], np.cumsum(0.5 * (ned[1:] + ned[:-1]) * 0.1, 0)])
    pos += rng.normal(0, 0.01, pos.shape)
    nu += rng.normal(0, 0.01, nu.shape)
    wrapped = (angles + np.pi) % (2 * np.pi) - np.pi
    return pd.DataFrame(
        {"t": t, "experiment": experiment, "x": pos[:, 0], "y": pos[:, 1], "z": pos[:, 2]}
        | dict(zip(("phi", "theta", "psi"), wrapped.T, strict=True))
        | dict(zip(("u", "v", "w"), nu.T, strict=True))
        | {"tau_X": np.ones(t.size)}
    )


def test_world_frame_velocities_under_body_names_are_refused():
    """u, v, w logged as NED velocities (a navigation filter's output under the body names)
    passed: every surge and sway fit read north and east as forward and starboard. The
    displacement of x, y is compared with u, v read both ways (velocity_frame_ratios)."""
    from nnid.datasets.log import velocity_frame_ratios
    from nnid.datasets.mapping import rotation_from_euler

    def turning(t):
        return 1.5 * np.sin(0.15 * t)

    a = _cruising_log(turning)
    b = _cruising_log(lambda t: np.full(t.size, 2.0), seed=1, experiment="b")  # holds its heading
    log = pd.concat([a, b], ignore_index=True)
    assert validate_log(log, "nav.csv") is log
    ratios = {name: ratio for name, ratio, *_ in velocity_frame_ratios(log)}
    assert ratios["a"] < 0.1 and 0.3 < ratios["b"] < 3  # turning: body; holding: can't tell
    ned = np.einsum(
        "nij,nj->ni",
        rotation_from_euler(log[["phi", "theta", "psi"]].to_numpy()),
        log[["u", "v", "w"]].to_numpy(),
    )
    slip = log.assign(u=ned[:, 0], v=ned[:, 1], w=ned[:, 2])
    said = (
        r"nav\.csv, field 'u': u, v, w look like world-frame \(NED\) velocities in experiment 'a'"
    )
    with pytest.raises(NnidInputError, match=said + r".*turn NED velocities by J₁\(Θ\)ᵀ"):
        validate_log(slip, "nav.csv")
    # the run that holds its heading alone cannot tell the frames apart: it passes
    held = slip[slip["experiment"] == "b"]
    assert validate_log(held, "nav.csv") is held
    # gaps (empty cells, a 3 s dropout) are stepped over
    gappy = slip.copy()
    gappy.loc[gappy.index % 13 == 0, "u"] = np.nan
    gappy = gappy.drop(index=range(200, 230))
    with pytest.raises(NnidInputError, match=said):
        validate_log(gappy, "nav.csv")
    # body velocities with a constant heading offset between the position's axes and the
    # compass (a pool frame), and a current: both absorbed, they pass
    c, s = math.cos(0.7), math.sin(0.7)
    offset = log.assign(
        x=c * log["x"] - s * log["y"] + 0.05 * log["t"], y=s * log["x"] + c * log["y"]
    )
    assert validate_log(offset, "nav.csv") is offset


def test_the_velocity_frame_check_turns_the_velocity_as_the_mapping_does():
    """north_east is rotation_from_euler's J₁ ν₁ written out: they agree on a tumbling
    attitude."""
    from nnid.datasets.log import north_east
    from nnid.datasets.mapping import rotation_from_euler

    rng = np.random.default_rng(3)
    angles = rng.uniform(-np.pi, np.pi, (50, 3)) * [1.0, 0.5, 1.0]
    nu = rng.normal(size=(50, 3))
    expected = np.einsum("nij,nj->ni", rotation_from_euler(angles), nu)
    assert np.allclose(np.stack(north_east(angles, nu), 1), expected[:, :2], atol=1e-12)


def test_a_pose_integrated_exactly_at_a_held_heading_is_no_world_frame():
    """Body velocities whose pose is their exact trapezoid integral at a held heading: both
    readings fit to rounding, and their ratio was one of rounding errors (12 at ψ = 1 rad:
    refused as NED velocities). Rounding now reads as equal residuals: about 1."""
    from scipy.integrate import cumulative_trapezoid

    from nnid.datasets.log import velocity_frame_ratios

    t = np.arange(0.0, 60.0, 0.1)
    u, v = 1.0 + 0.5 * np.sin(0.3 * t), 0.2 * np.cos(0.2 * t)
    for heading in (0.5, 1.0, 2.0, -2.5):
        c, s = math.cos(heading), math.sin(heading)
        log = pd.DataFrame(
            {"t": t, "x": cumulative_trapezoid(c * u - s * v, t, initial=0.0),
             "y": cumulative_trapezoid(s * u + c * v, t, initial=0.0), "z": 0.0, "phi": 0.0,
             "theta": 0.0, "psi": heading, "u": u, "v": v, "w": 0.0, "tau_X": 1.0}
        )  # fmt: skip
        [(_, ratio, fit, _)] = velocity_frame_ratios(log)
        assert fit > 0.99 and abs(ratio - 1.0) < 1e-3, (heading, ratio)
        assert validate_log(log, "exact.csv") is log


def test_the_velocity_frame_check_counts_the_seconds_that_hold_velocities():
    """Windows over empty u, v, w cells hold no evidence of the frame: a minute whose
    velocities stop after 12 s counted 58 s of windows (the 20 s the check asks for); it
    counts the seconds with data."""
    from nnid.datasets.log import velocity_frame_ratios

    log = _cruising_log(lambda t: 1.5 * np.sin(0.15 * t))
    log.loc[log["t"] > 12.0, ["u", "v", "w"]] = np.nan
    [(_, _, _, seconds)] = velocity_frame_ratios(log)
    assert 9.0 < seconds < 12.0, seconds


def _diving_by_pitch(pitched: bool) -> pd.DataFrame:
    """A 1.5-m/s run whose depth changes through its pitch (−sin θ u, a torpedo AUV) or
    through its heave w at level attitude, z the depth it implies."""
    t = np.arange(0.0, 120.0, 0.05)
    theta = 0.3 * np.sin(0.2 * t) if pitched else np.zeros_like(t)
    w = np.zeros_like(t) if pitched else 0.4 * np.sin(0.2 * t)
    u = np.full_like(t, 1.5)
    rate = -np.sin(theta) * u + np.cos(theta) * w
    z = 5.0 + np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * 0.05)])
    zero = np.zeros_like(t)
    return pd.DataFrame({"t": t, "z": z, "phi": zero, "theta": theta, "psi": zero, "u": u,
                         "v": zero, "w": w, "tau_X": np.full_like(t, 10.0)})  # fmt: skip


def test_a_turned_pitch_is_named_beside_a_turned_depth():
    """A run that dives by pitching reads slope −1 with θ turned (nose down positive) just as
    with z turned: the refusal named only z and w, and turning z as it advised passed a log
    whose θ and z were both wrong. It names θ there; a run that heaves level is not told
    of θ, which plays no part in its depth."""
    pitched = _diving_by_pitch(True)
    validate_log(pitched, "ok")
    with pytest.raises(NnidInputError, match="or theta is turned"):
        validate_log(pitched.assign(theta=-pitched["theta"]), "pitch")
    with pytest.raises(NnidInputError, match="or theta is turned"):
        validate_log(pitched.assign(z=-pitched["z"]), "height")  # the same to the depth alone
    level = _diving_by_pitch(False)
    validate_log(level, "ok")
    with pytest.raises(NnidInputError, match="a height or altitude is −z") as err:
        validate_log(level.assign(z=-level["z"]), "height")
    assert "theta" not in str(err.value)


def _every(log: pd.DataFrame, columns: list[str], k: int) -> pd.DataFrame:
    """``log`` with ``columns`` logged at a k-th of the clock's rate: empty between samples, as
    a slower sensor merged on one time column is (a depth sensor beside a faster DVL)."""
    out = log.copy()
    out.loc[out.index % k != 0, columns] = np.nan
    return out


def test_the_depth_check_reads_a_depth_logged_slower_than_the_velocities():
    """z every 10th row beside u, v, w every row (a 2-Hz depth sensor and a 20-Hz DVL on one
    clock): every step met an empty z, every window was empty, and cm/s velocities passed. The
    velocities' steps are now summed between z's samples (depth_slopes); and a DVL slower than
    the depth sensor is read across its samples the same way."""
    from nnid.datasets.log import depth_slopes

    level = _diving_by_pitch(False).assign(u=0.3)  # 0.4 m/s of heave
    [(_, dense, _, seconds)] = depth_slopes(level)
    for sparse in (_every(level, ["z"], 10), _every(level, ["u", "v", "w"], 10)):
        [(_, slope, fit, sparse_seconds)] = depth_slopes(sparse)
        assert abs(slope - dense) < 0.01 and fit > 0.99 and sparse_seconds > 0.9 * seconds
        assert validate_log(sparse, "m.csv") is sparse  # m/s: passes
        cm = sparse.assign(**{c: 100 * sparse[c] for c in "uvw"})
        with pytest.raises(
            NnidInputError, match=r"field 'w'.*(99\.\d|100) times as fast.*cm/s"
        ) as err:
            validate_log(cm, "cm.csv")
        assert err.value.field == "w"
        with pytest.raises(NnidInputError, match="a height or altitude is −z"):
            validate_log(sparse.assign(z=-sparse["z"]), "height.csv")


def test_the_rate_check_reads_an_attitude_logged_slower_than_the_gyro():
    """The attitude every 5th row beside a gyro every row (or the gyro the slower one): a gyro
    in deg/s passed, no step having the whole attitude at both ends. The gyro's steps are
    summed between the attitude's samples (rate_slopes)."""
    from nnid.datasets.log import rate_slopes

    log = _turning_log(_wobble, seconds=30.0)
    for sparse in (_every(log, list(ANGLES), 5), _every(log, ["p", "q", "r"], 5)):
        assert all(0.97 < slope < 1.03 for *_, slope, _ in rate_slopes(sparse))
        assert validate_log(sparse, "imu.csv") is sparse  # rad/s: passes
        with pytest.raises(NnidInputError, match=r"field 'r'.*r reads 5\d\.\d times.*deg/s"):
            validate_log(sparse.assign(r=np.degrees(sparse["r"])), "imu.csv")


def test_the_velocity_frame_check_reads_a_position_logged_slower_than_the_velocities():
    """x, y every 10th row (a 1-Hz position fix beside a 10-Hz DVL): NED velocities under the
    body names passed, every step meeting an empty position; the displacement between fixes
    is now compared with the velocities summed across it."""
    from nnid.datasets.mapping import rotation_from_euler

    log = _every(_cruising_log(lambda t: 1.5 * np.sin(0.15 * t)), ["x", "y"], 10)
    assert validate_log(log, "nav.csv") is log
    ned = np.einsum(
        "nij,nj->ni",
        rotation_from_euler(log[list(ANGLES)].to_numpy()),
        log[["u", "v", "w"]].to_numpy(),
    )
    with pytest.raises(NnidInputError, match=r"field 'u'.*world-frame \(NED\) velocities"):
        validate_log(log.assign(u=ned[:, 0], v=ned[:, 1], w=ned[:, 2]), "nav.csv")


def test_a_dropout_longer_than_two_windows_is_not_read_across():
    """A depth that drops out for 10 s (two windows of 2 s are 4 s) is a gap, not a slower
    sensor: its span is left out of both sums, as its steps were before."""
    from nnid.datasets.log import depth_slopes

    level = _diving_by_pitch(False).assign(u=0.3)
    [(_, _, _, seconds)] = depth_slopes(level)
    gap = level.copy()
    gap.loc[(gap["t"] > 50.0) & (gap["t"] < 60.0), "z"] = np.nan
    [(_, slope, _, gap_seconds)] = depth_slopes(gap)
    assert abs(slope - 1.0) < 0.01 and seconds - 12.0 < gap_seconds < seconds - 8.0


def test_each_experiments_step_is_the_rule_s_whichever_way_it_is_read():
    """_experiment_steps reads each experiment's median at once and puts through the
    rounded-clock rule (clock_step) only those its vectorised screen (one step to float
    error) cannot settle (a log
    a reader cut into 10^4 pieces took half a second a call one experiment at a time). On
    clocks of every kind, among them rounded ones, a resumed run and a NaN stamp, every
    step is clock_step's to the bit, and only rounded clocks go through the rule."""
    from itertools import pairwise

    from nnid.datasets.log import _experiment_steps, _plain_steps, clock_step

    rng = np.random.default_rng(3)
    k = np.arange(240)
    clocks = {
        "grid": k * 0.05,
        "ms120": np.round(k / 120 * 1e3) / 1e3,
        "epoch": 1.7e9 + np.round(k / 120, 3),
        "jitter": 100.0 + np.cumsum(rng.normal(0.01, 1e-4, k.size)),
        "us": np.round(np.cumsum(rng.normal(0.01, 1e-4, k.size)), 6),
        "two": np.cumsum(rng.choice([0.01, 0.1], k.size)),
        "alternate": np.cumsum(np.tile([0.04, 0.06], k.size // 2)),
        "one": np.zeros(1),
        "nan": np.r_[k[:5] * 0.1, np.nan, k[6:20] * 0.1],
    }
    parts = [pd.DataFrame({"experiment": name, "t": t}) for name, t in clocks.items()]
    # ms120 resumes after the others' rows
    parts.append(pd.DataFrame({"experiment": "ms120", "t": np.round((5 + k / 120) * 1e3) / 1e3}))
    log = pd.concat(parts, ignore_index=True)
    codes, names = pd.factorize(log["experiment"])
    order = np.argsort(codes, kind="stable")
    codes, t = codes[order], log["t"].to_numpy(np.float64)[order]
    step = _experiment_steps(codes, order, t, len(names))
    bounds = np.searchsorted(codes, np.arange(len(names) + 1))
    within = (codes[1:] == codes[:-1]) & (np.diff(order) == 1)
    rule = [clock_step(t[a:b], within[a : b - 1])[0] for a, b in pairwise(bounds)]
    np.testing.assert_array_equal(step, rule)
    assert step[names.get_loc("ms120")] == pytest.approx(1 / 120, rel=1e-4)
    ruled = _plain_steps(codes, t, within, bounds)[1]
    # a grid (one step to float error) and a run of one row keep their median unasked; a
    # rounded clock and a NaN stamp are asked
    assert not ruled[[names.get_loc("grid"), names.get_loc("one")]].any()
    assert ruled[[names.get_loc(c) for c in ("ms120", "epoch", "nan")]].all()


def test_an_experiment_written_row_by_row_with_another_reads_all_its_steps():
    """Two loggers written row by row (a, b, a, b, ...), b dropping one row: a's rows are side
    by side once. Read over that one step alone, a's step was one 8- or 9-ms step of its
    120 Hz clock stamped in whole ms; interleaved, all its steps in time order are read."""
    from nnid.datasets.log import _experiment_sorted

    k = np.arange(300)
    a = pd.DataFrame({"experiment": "a", "t": np.round(k / 120 * 1e3) / 1e3})
    b = pd.DataFrame({"experiment": "b", "t": k / 100 + 0.002})
    log = pd.concat([a, b]).sort_index(kind="stable").reset_index(drop=True)
    log = log.drop(index=2 * 150 + 1).reset_index(drop=True)  # b's row 150
    _, names, *_, step = _experiment_sorted(log)
    assert step[list(names).index("a")] == pytest.approx(1 / 120, rel=1e-4)
    assert step[list(names).index("b")] == pytest.approx(1 / 100, rel=1e-9)
