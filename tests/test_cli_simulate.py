"""`nnid simulate` end to end, and bad vehicle files and configs: exit 2 and one message."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from nnid.cli import app
from nnid.datasets.readers import read_log

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()

GOOD_VEHICLE = """
name = "box"
mass = 30.0
inertia = [1.0, 2.0, 2.0]
[added_mass]
X_udot = -10.0
[damping]
model = "weiss_quadratic"
[damping.coefficients]
"X:u*abs(u)" = -40.0
"""

CONFIG = """
vehicle = "{vehicle}"
dt = 0.05
[[experiments]]
name = "surge"
signals = [{{ kind = "step", channel = "X", amplitude = 10.0, duration = 5.0 }}]
"""


def _write(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_seamor_sequence_log_is_valid_and_in_weiss_order(tmp_path):
    """The bundled config simulates Weiss's sequence; the log passes the validator."""
    out = tmp_path / "x.parquet"
    result = runner.invoke(
        app, ["simulate", str(ROOT / "configs/seamor_sequence.toml"), "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    log = read_log(out)
    order = list(dict.fromkeys(log["experiment"]))
    assert order[:5] == ["surge", "sway", "heave", "roll", "yaw"]
    assert "surge-heave" in order and "surge-sway-yaw" in order
    assert {"x", "y", "z", "phi", "theta", "psi", "tau_X", "tau_N"} <= set(log.columns)
    # the decoupled surge run excites surge only, and the vehicle moves
    surge = log[log["experiment"] == "surge"]
    assert (
        surge["tau_X"].abs().max() > 0
        and surge[["tau_Y", "tau_Z", "tau_K", "tau_N"]].abs().max().max() == 0
    )
    assert surge["true_u"].abs().max() > 0.3
    assert (log.groupby("experiment")["t"].diff().dropna() > 0).all()


def test_simulate_is_deterministic_for_a_seed(tmp_path):
    veh = _write(tmp_path, "box.toml", GOOD_VEHICLE)
    cfg = _write(
        tmp_path, "sim.toml", CONFIG.format(vehicle=veh) + '[measurement]\nkind = "mocap"\n'
    )
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    for out in (a, b):
        assert (
            runner.invoke(app, ["simulate", str(cfg), "--out", str(out), "--seed", "3"]).exit_code
            == 0
        )
    pd.testing.assert_frame_equal(pd.read_csv(a), pd.read_csv(b))
    c = tmp_path / "c.csv"
    runner.invoke(app, ["simulate", str(cfg), "--out", str(c), "--seed", "4"])
    assert not pd.read_csv(a)["x"].equals(pd.read_csv(c)["x"])


BAD_VEHICLES = {
    "missing mass": (GOOD_VEHICLE.replace("mass = 30.0\n", ""), "mass", "required"),
    "negative mass": (GOOD_VEHICLE.replace("mass = 30.0", "mass = -3.0"), "mass", "greater than 0"),
    "inertia not PD": (
        GOOD_VEHICLE.replace("[1.0, 2.0, 2.0]", "[1.0, -2.0, 2.0]"),
        "inertia",
        "positive definite",
    ),
    "unknown mask": (
        GOOD_VEHICLE.replace("weiss_quadratic", "magic"),
        "damping.model",
        "unknown damping model",
    ),
    "wrong type": (GOOD_VEHICLE.replace("mass = 30.0", 'mass = "heavy"'), "mass", "number"),
    "bad term": (
        GOOD_VEHICLE.replace('"X:u*abs(u)"', '"X:u*zz"'),
        "damping.coefficients",
        "not a factor",
    ),
    "bad added mass key": (GOOD_VEHICLE.replace("X_udot", "X_xdot"), "added_mass", "X_xdot"),
    "unknown field": ("colour = 'yellow'\n" + GOOD_VEHICLE, "colour", "not a known field"),
    "bad installation key": (
        GOOD_VEHICLE.replace("[added_mass]", '[installation]\n"w.up" = 0.5\n[added_mass]'),
        "installation",
        "<dof>.<pos|neg>",
    ),
    "zero thruster direction": (
        GOOD_VEHICLE
        + '[[thrusters]]\nname = "T1"\nposition = [0, 0, 0]\ndirection = [0, 0, 0]\n'
        + 'curve = { kind = "signed_quadratic", k = 1.0 }\n',
        "thrusters.0.direction",
        "non-zero",
    ),
    "broken toml": (GOOD_VEHICLE.replace("mass = 30.0", "mass = = 30"), None, "not valid TOML"),
}


def test_a_toml_file_with_a_byte_order_mark_is_read_and_latin_1_is_located(tmp_path):
    """Notepad's UTF-8 BOM was "not valid TOML (at line 1, column 1)"; a Latin-1 'é' in a
    comment was "not a text file", with no line."""
    veh = tmp_path / "bom.toml"
    veh.write_bytes(b"\xef\xbb\xbf" + GOOD_VEHICLE.encode())
    cfg = _write(tmp_path, "sim.toml", CONFIG.format(vehicle=veh))
    result = runner.invoke(app, ["simulate", str(cfg), "--out", str(tmp_path / "x.csv")])
    assert result.exit_code == 0, result.output
    veh.write_bytes(("# r\u00e9glage\n" + GOOD_VEHICLE).encode("latin-1"))
    result = runner.invoke(app, ["simulate", str(cfg), "--out", str(tmp_path / "y.csv")])
    assert result.exit_code == 2
    assert "bom.toml: is not UTF-8 text at line 1 (byte 3): save it as UTF-8" in result.output


@pytest.mark.parametrize("case", sorted(BAD_VEHICLES))
def test_bad_vehicle_file_exits_2_naming_the_field(tmp_path, case):
    text, field, words = BAD_VEHICLES[case]
    veh = _write(tmp_path, "bad.toml", text)
    cfg = _write(tmp_path, "sim.toml", CONFIG.format(vehicle=veh))
    result = runner.invoke(app, ["simulate", str(cfg), "--out", str(tmp_path / "x.csv")])
    assert result.exit_code == 2
    message = result.output.strip()
    assert "Traceback" not in message and len(message.splitlines()) == 1, message
    assert "bad.toml" in message and words in message
    if field:
        assert f"'{field}'" in message
    assert not (tmp_path / "x.csv").exists()


BAD_CONFIGS = {
    "unknown signal kind": (
        CONFIG.replace('kind = "step"', 'kind = "wiggle"'),
        "experiments.0.signals.0.kind",
    ),
    "negative dt": (CONFIG.replace("dt = 0.05", "dt = -0.05"), "dt"),
    "unknown channel": (
        CONFIG.replace('channel = "X"', 'channel = "Q"'),
        "experiments.0.signals.0.channel",
    ),
    "unknown effect": (CONFIG + '[[effects]]\nname = "gremlins"\nvalue = 1.0\n', "effects.0.name"),
    "missing vehicle": (CONFIG.replace('vehicle = "{vehicle}"', ""), "vehicle"),
    # said as "the simulation diverged", or coerced (true was 1 N)
    "nan amplitude": (
        CONFIG.replace("amplitude = 10.0", "amplitude = nan"),
        "experiments.0.signals.0.amplitude",
    ),
    "amplitude true": (
        CONFIG.replace("amplitude = 10.0", "amplitude = true"),
        "experiments.0.signals.0.amplitude",
    ),
    "noise as text": (
        CONFIG + '[measurement]\nkind = "mocap"\nposition_noise = "0.01"\n',
        "measurement.position_noise",
    ),
    # tracebacks
    "two velocity biases": (
        CONFIG + '[measurement]\nkind = "dvl_imu"\nvelocity_bias = [0.1, 0.0]\n',
        "measurement.velocity_bias",
    ),
    "nothing to simulate": (CONFIG.split("[[experiments]]")[0], "nothing to simulate"),
    "an effect no vehicle has": (
        CONFIG + '[[effects]]\nname = "added_mass.u"\nvalue = 1e6\n',
        "effects",
    ),
    "aprbs seed negative": (
        CONFIG.replace(
            'kind = "step", channel = "X", amplitude = 10.0, duration = 5.0',
            'kind = "aprbs", channel = "X", amplitude = 10.0, hold_min = 0.5, hold_max = 1.0, '
            "duration = 5.0, seed = -1",
        ),
        "experiments.0.signals.0.seed",
    ),
    # out of memory, killed
    "dt in nanoseconds": (CONFIG.replace("dt = 0.05", "dt = 1e-9"), "is dt in seconds?"),
    # accepted without a word: aliased, applied twice, ignored
    "a chirp past nyquist": (
        CONFIG.replace(
            'kind = "step", channel = "X", amplitude = 10.0, duration = 5.0',
            'kind = "chirp", channel = "X", amplitude = 10.0, f0 = 0.1, f1 = 50.0, duration = 5.0',
        ),
        "reaches 50 Hz, at or above the 10 Hz",
    ),
    "an effect twice": (
        CONFIG + '[[effects]]\nname = "buoyancy_offset"\nvalue = 1.0\n'
        '[[effects]]\nname = "buoyancy_offset"\nvalue = 2.0\n',
        "buoyancy_offset given twice",
    ),
    "a noise the sensor does not have": (
        CONFIG + '[measurement]\nkind = "mocap"\nvelocity_noise = 0.1\n',
        "does not use velocity_noise",
    ),
    "an angle of x0 in degrees": (
        CONFIG.replace('name = "surge"', 'name = "surge"\nx0 = [0, 0, 0, 0, 0, 180]'),
        "experiments.0.x0",
    ),
    # accepted without a word: a signal that never acts, levels never sampled, noise unread,
    # an autopilot of positive feedback or a heading in degrees
    "a signal after the end": (
        CONFIG.replace("duration = 5.0 }", "duration = 5.0, start = 1.0 }") + "duration = 0.5\n",
        "experiments.0.signals.0.start",
    ),
    "levels held shorter than dt": (
        CONFIG.replace(
            'kind = "step", channel = "X", amplitude = 10.0, duration = 5.0',
            'kind = "stairs", channel = "X", levels = [10.0, -10.0], hold = 0.04',
        ),
        "experiments.0.signals.0.hold",
    ),
    "aprbs levels held shorter than dt": (
        CONFIG.replace(
            'kind = "step", channel = "X", amplitude = 10.0, duration = 5.0',
            'kind = "aprbs", channel = "X", amplitude = 10.0, hold_min = 0.01, hold_max = 1.0, '
            "duration = 5.0",
        ),
        "experiments.0.signals.0.hold_min",
    ),
    # flown as a whole sample or, falling between two, not at all (forces zero, log written)
    "a pulse shorter than dt": (
        CONFIG.replace("duration = 5.0 }", "duration = 0.01, start = 0.02 }") + "duration = 1.0\n",
        "experiments.0.signals.0.duration",
    ),
    "a noise level without a kind": (
        CONFIG + "[measurement]\nvelocity_noise = 0.5\n",
        "set without a kind",
    ),
    # flown as rounding noise scaled to the amplitude, or at f_min while f_max was checked
    "a multisine of one frequency": (
        CONFIG.replace(
            'kind = "step", channel = "X", amplitude = 10.0, duration = 5.0',
            'kind = "multisine", channel = "X", amplitude = 10.0, f_min = 0.5, f_max = 0.5, '
            "duration = 5.0",
        ),
        "experiments.0.signals.0",
    ),
    "a one-sine multisine with a band": (
        CONFIG.replace(
            'kind = "step", channel = "X", amplitude = 10.0, duration = 5.0',
            'kind = "multisine", channel = "X", amplitude = 10.0, f_min = 0.5, f_max = 2.0, '
            "n = 1, duration = 5.0",
        ),
        "experiments.0.signals.0",
    ),
    # said as "starts at 5 s, at or after the experiment's end (5 s)": give it a duration
    "a held step that sets the experiment's end": (
        CONFIG.replace("amplitude = 10.0, duration = 5.0", "amplitude = 10.0, start = 5.0"),
        "experiments.0.duration",
    ),
    "an autopilot of positive feedback": (
        CONFIG + "[autopilot]\nkp = [0, 0, -50, 0, 0, 0]\n",
        "autopilot.kp.2",
    ),
    "an autopilot heading in degrees": (
        CONFIG + "[autopilot]\nkp = [0, 0, 0, 0, 0, 5]\nreference = [0, 0, 0, 0, 0, 90]\n",
        "autopilot.reference",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_CONFIGS))
def test_bad_config_exits_2_naming_the_field(tmp_path, case):
    text, field = BAD_CONFIGS[case]
    veh = _write(tmp_path, "box.toml", GOOD_VEHICLE)
    cfg = _write(tmp_path, "sim.toml", text.format(vehicle=veh))
    result = runner.invoke(app, ["simulate", str(cfg), "--out", str(tmp_path / "x.csv")])
    assert result.exit_code == 2, result.output
    assert (f"'{field}'" if "." in field or " " not in field else field) in result.output
    assert "sim.toml" in result.output
    assert len(result.output.strip().splitlines()) == 1


def test_a_sequence_of_forces_on_a_thruster_vehicle_names_the_sequence(tmp_path):
    """It named 'experiments.0.signals.0.channel', a key the config does not have."""
    args = ["simulate", str(ROOT / "configs/seamor_sequence.toml"), "--vehicle", "bluerov2_heavy"]
    result = runner.invoke(app, [*args, "--out", str(tmp_path / "x.csv")])
    assert result.exit_code == 2
    assert "field 'sequence': the sequence drives the forces X, Y, Z, K, M, N" in result.output


def test_an_existing_out_file_is_replaced_only_with_force(tmp_path):
    veh = _write(tmp_path, "box.toml", GOOD_VEHICLE)
    cfg = _write(tmp_path, "sim.toml", CONFIG.format(vehicle=veh))
    log = _write(tmp_path, "measured.csv", "a measured log\n")
    result = runner.invoke(app, ["simulate", str(cfg), "--out", str(log)])
    assert result.exit_code == 2 and "give --force to replace it" in result.output
    assert log.read_text() == "a measured log\n"
    result = runner.invoke(app, ["simulate", str(cfg), "--out", str(log), "--force"])
    assert result.exit_code == 0 and read_log(log)["experiment"].iloc[0] == "surge"


def test_version():
    from nnid import __version__

    res = runner.invoke(app, ["--version"])
    assert res.exit_code == 0 and res.output.strip() == f"nnid {__version__}"


@pytest.mark.parametrize(("command", "words"), [("compare", "config's [[models]]"),
                                              ("sweep", "with a [sweep] table")])  # fmt: skip
def test_help_keeps_the_toml_tables_and_rewraps_docstrings(command, words, monkeypatch):
    """Help text is Markdown, not Rich markup: a TOML table name in brackets is text, and a
    docstring's line breaks do not break a sentence that fits on one line."""
    monkeypatch.setenv("COLUMNS", "140")  # Rich's width: every summary fits on one row
    res = runner.invoke(app, [command, "--help"])
    assert res.exit_code == 0
    flat = " ".join(" ".join(line.strip(" │").split()) for line in res.output.splitlines())
    assert words in flat, res.output
    listing = runner.invoke(app, ["--help"]).output
    row = next(row for row in listing.splitlines() if " inspect " in row)
    assert "derivable signals and the excitation of each DOF" in " ".join(row.split()), listing


def test_help_says_what_the_code_does_without_asking(monkeypatch):
    """sweep exits 1 and writes no best.toml when no setting got a score, detect's --window
    defaults to the detection model's and its --columns is refused with --follow: none of it
    was in --help."""
    monkeypatch.setenv("COLUMNS", "140")

    def flat(command: str) -> str:
        res = runner.invoke(app, [command, "--help"])
        assert res.exit_code == 0
        return " ".join(" ".join(line.strip(" │").split()) for line in res.output.splitlines())

    assert "best.toml is not written and the command exits 1" in flat("sweep")
    said = flat("detect")
    assert "default the detection model's ([detect] window_s" in said, said
    assert "format (not with --follow)" in said, said


def test_inspect_on_a_folder_asks_for_a_reader_config(tmp_path):
    res = runner.invoke(app, ["inspect", str(tmp_path)])
    assert res.exit_code == 2 and "--columns" in res.output and str(tmp_path) in res.output


def test_unknown_preset_and_missing_options(tmp_path):
    cfg = _write(tmp_path, "sim.toml", CONFIG.format(vehicle="nautilus"))
    result = runner.invoke(app, ["simulate", str(cfg), "--out", str(tmp_path / "x.csv")])
    assert result.exit_code == 2 and "neither a preset" in result.output
    res = runner.invoke(app, ["detect"])
    assert res.exit_code == 2 and "--model" in res.output
    res = runner.invoke(app, ["loop", "--out", str(tmp_path / "o")])  # neither log nor vehicle
    assert res.exit_code == 2 and "give a vehicle" in res.output


def test_config_vehicle_file_is_relative_to_the_config(tmp_path, monkeypatch):
    """`vehicle = "boat.toml"` in a config in another folder is that folder's file (as for
    train and loop), whatever the working directory; a missing one names the config's key."""
    (tmp_path / "cfg").mkdir()
    preset = ROOT / "nnid" / "presets" / "seamor.toml"
    _write(tmp_path / "cfg", "boat.toml", preset.read_text())
    cfg = _write(tmp_path / "cfg", "sim.toml", CONFIG.format(vehicle="boat.toml"))
    monkeypatch.chdir(tmp_path)
    res = runner.invoke(app, ["simulate", "cfg/sim.toml", "--out", str(tmp_path / "x.csv")])
    assert res.exit_code == 0 and "of 'seamor'" in res.output, res.output
    cfg.write_text(CONFIG.format(vehicle="raft.toml"))
    res = runner.invoke(app, ["simulate", "cfg/sim.toml", "--out", str(tmp_path / "y.csv")])
    assert res.exit_code == 2 and "sim.toml, field 'vehicle'" in res.output, res.output
    assert "raft.toml" in res.output and not (tmp_path / "y.csv").exists()


def test_a_doptimal_sine_is_checked_against_nyquist_in_hz():
    """Its frequency is computed (rad/s, from the model): the Nyquist check took the method
    for a number and raised a TypeError on every d-optimal config."""
    from nnid.config import SimulateConfig

    signal = {"kind": "doptimal_sine", "channel": "X", "offset": 10.0, "amplitude": 5.0,
              "inertia": 50.0, "k_linear": 5.0, "duration": 20.0}  # fmt: skip
    cfg = {"vehicle": "seamor", "experiments": [{"name": "a", "signals": [signal]}]}
    sine = SimulateConfig.model_validate(cfg).experiments[0].signals[0]
    assert sine.top_frequency() == pytest.approx(sine.frequency() / (2 * math.pi))
    stiff = {**signal, "inertia": 1e-6, "k_linear": 1e3}  # ω far above π / dt
    with pytest.raises(ValueError, match="its doptimal_sine reaches"):
        SimulateConfig.model_validate({**cfg, "experiments": [{"name": "a", "signals": [stiff]}]})


def test_a_doptimal_sine_on_a_thruster_is_refused_naming_its_channel():
    """Its frequency is designed from its offset as a force (Caccia eqs 13-14), while an
    offset on a thruster is a command (docs: signal keys): a PWM offset was read as newtons.
    Flown on a generalized force; refused on a thruster, naming the channel."""
    from nnid.config import Experiment
    from nnid.datasets.simulator import experiment_inputs
    from nnid.errors import NnidInputError

    signal = {"kind": "doptimal_sine", "channel": "AS", "offset": 50.0, "amplitude": 20.0,
              "inertia": 20.0, "k_linear": 10.0, "duration": 10.0}  # fmt: skip
    on_thruster = Experiment(name="d", signals=[signal])
    with pytest.raises(NnidInputError, match="'AS' is a thruster, whose offset is a command"
                       ) as err:  # fmt: skip
        experiment_inputs(on_thruster, ("AS", "AP"), 0.1, where="experiments.0.")
    assert err.value.field == "experiments.0.signals.0.channel"
    on_force = Experiment(name="d", signals=[{**signal, "channel": "X"}])
    assert experiment_inputs(on_force, tuple("XYZKMN"), 0.1)[:, 0].max() > 50.0


@pytest.mark.parametrize(("args", "words"), [
    (["train", "--bogus"], "No such option: --bogus"),
    (["detect", "--window", "5s", "a.csv"], "Invalid value for '--window'"),
    (["bogus"], "No such command 'bogus'"),
])  # fmt: skip
def test_a_command_line_parse_error_is_one_line_and_exit_2(args, words):
    """Through the console entry (``main``), as a person runs it: an unknown option, a value of
    the wrong type or an unknown command is one ``error:`` line naming it and the command's
    help, not typer's five-line box; a bare ``nnid`` still prints the help."""
    import subprocess
    import sys

    cmd = [sys.executable, "-c", "from nnid.cli import main; main()"]
    res = subprocess.run([*cmd, *args], capture_output=True, text=True, timeout=120)
    lines = res.stderr.strip().splitlines()
    assert res.returncode == 2 and len(lines) == 1, res.stderr
    assert lines[0].startswith("error: ") and words in lines[0] and "--help" in lines[0]
    bare = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert bare.returncode == 2 and "Commands" in bare.stdout + bare.stderr


def test_commands_in_pwm_against_a_thrust_table_are_warned_of(tmp_path):
    """bluerov2_heavy's thrusters give no cmd_min/cmd_max: commands of 1500 ± 400 (PWM
    microseconds) were flown at the table's last thrust without a word, and the loop then
    found a centre-of-gravity shift in the tumbling log. The table's span is the range."""
    import warnings

    from nnid.datasets.arrays import command_range, warn_far_beyond_range
    from nnid.vehicle import load_vehicle

    heavy = load_vehicle("bluerov2_heavy")
    assert heavy.thrusters[0].cmd_min is None and command_range(heavy.thrusters[0]) == (-1, 1)
    # the range the simulator flies, one rule with the saturation warning's: cmd_min/cmd_max
    # of ±2 over a table of ±1 fly ±1 (it said ±2), and one bound clips with the table's other
    wide = heavy.thrusters[0].model_copy(update={"cmd_min": -2.0, "cmd_max": 2.0})
    assert command_range(wide) == (-1, 1)
    assert command_range(wide.model_copy(update={"cmd_min": None, "cmd_max": 0.5})) == (-1, 0.5)
    pwm = pd.DataFrame({f"cmd_{t.name}": [1500.0, 1900.0] for t in heavy.thrusters})
    with pytest.warns(UserWarning, match=r"cmd_t1 reaches 1900, far beyond thruster t1's range"):
        warn_far_beyond_range(pwm, heavy)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warn_far_beyond_range(pwm / 2000.0, heavy)
    cfg = _write(tmp_path, "pwm.toml", 'vehicle = "bluerov2_heavy"\ndt = 0.05\n[[experiments]]\n'
                 'name = "a"\nsignals = [{ kind = "step", channel = "t1", amplitude = 1900.0, '
                 "duration = 1.0 }]\n")  # fmt: skip
    result = runner.invoke(app, ["simulate", str(cfg), "--out", str(tmp_path / "x.csv")])
    assert "cmd_t1 reaches 1900, far beyond thruster t1's range [-1, 1]" in result.output
    # one slip, one warning: not again as a saturation of the same thruster
    assert "flown at its bound" not in result.output


def test_a_vehicle_whose_mass_matrix_is_not_positive_definite_is_named(tmp_path, monkeypatch):
    """X_udot = +40 on a 30 kg vehicle (M = M_RB + M_A not positive definite): simulate said
    it against the simulate config, with no field, never the vehicle file. The file still
    loads (a fit refits its added mass): only what flies it refuses it."""
    from nnid.vehicle import load_vehicle

    veh = _write(tmp_path, "heavy.toml", GOOD_VEHICLE.replace("X_udot = -10.0", "X_udot = 40.0"))
    assert load_vehicle(veh).added_mass["X_udot"] == 40.0
    cfg = _write(tmp_path, "sim.toml", CONFIG.format(vehicle="heavy.toml"))
    monkeypatch.chdir(tmp_path)
    for extra in ([], ["--vehicle", str(veh)]):
        res = runner.invoke(app, ["simulate", str(cfg), "--out", "x.csv", *extra])
        assert res.exit_code == 2, res.output
        error = [line for line in res.output.splitlines() if line.startswith("error:")]
        assert len(error) == 1 and "not positive definite" in error[0], res.output
        assert "heavy.toml, field 'added_mass'" in error[0] and "sim.toml" not in error[0]
        assert not (tmp_path / "x.csv").exists()


def test_a_signal_cut_by_its_experiments_duration_is_said(tmp_path):
    """A 5-s step in an experiment of 2 s was flown for 2 s without a word: the rest of the
    signal the config asked for was dropped in silence. Said, naming the signal; a signal
    that fits its experiment is not."""
    veh = _write(tmp_path, "box.toml", GOOD_VEHICLE)
    fits = _write(tmp_path, "fits.toml", CONFIG.format(vehicle=veh))
    cut = _write(
        tmp_path,
        "cut.toml",
        CONFIG.format(vehicle=veh).replace('name = "surge"', 'name = "surge"\nduration = 2.0'),
    )
    said = "experiments.0.signals.0: the signal ends at 5 s, after the experiment's end (2 s"
    for config, expected in ((fits, False), (cut, True)):
        result = runner.invoke(
            app, ["simulate", str(config), "--out", str(tmp_path / f"{config.stem}.parquet")]
        )
        assert result.exit_code == 0, result.output
        assert (said in result.output) is expected, result.output
        assert ("its last 3 s are not flown" in result.output) is expected


def _run(name: str, signal: str = "", duration: str = "") -> str:
    """One more [[experiments]] table of a simulate config."""
    step = "{ kind = 'step', channel = 'X', amplitude = 1.0, duration = 5.0 }"
    signals = f"signals = [{step}{', ' + signal if signal else ''}]\n"
    return f"[[experiments]]\nname = '{name}'\n{duration}{signals}"


@pytest.mark.parametrize(("runs", "field", "expected"), [
    (_run("b") + _run("surge"), "experiments.2.name", "also by experiments.0"),
    (_run("b") + _run("c", "{ kind = 'chirp', channel = 'X', amplitude = 1.0, f0 = 0.1, "
                           "f1 = 50.0, duration = 5.0 }"),
     "experiments.2.signals.1.f1", "expected below 10 Hz"),
    (_run("b") + _run("c", "{ kind = 'sine', channel = 'X', amplitude = 1.0, frequency = 12.0, "
                           "duration = 5.0 }"),
     "experiments.2.signals.1.frequency", "expected below 10 Hz"),
    (_run("b") + _run("c", duration="duration = 0.01\n"), "experiments.2.duration",
     "expected at least one step (0.05 s)"),
], ids=["a name twice", "a chirp past nyquist", "a sine past nyquist",
        "a run under one step"])  # fmt: skip
def test_a_run_check_names_the_experiments_key_and_what_is_expected(
    tmp_path, runs, field, expected
):
    """A signal above Nyquist, a name given twice and a run under one step named the
    experiment but no key: the message was 'sim.toml: experiment 'c': ...'."""
    veh = _write(tmp_path, "box.toml", GOOD_VEHICLE)
    cfg = _write(tmp_path, "sim.toml", CONFIG.format(vehicle=veh) + runs)
    result = runner.invoke(app, ["simulate", str(cfg), "--out", str(tmp_path / "x.csv")])
    assert result.exit_code == 2, result.output
    assert f"sim.toml, field '{field}': " in result.output, result.output
    assert expected in result.output and len(result.output.strip().splitlines()) == 1


def test_a_sequence_run_named_twice_names_the_explicit_experiments_name():
    """A run of the [sequence] has a fixed name: the explicit experiment's name is the key."""
    from nnid.config import SimulateConfig
    from nnid.errors import NnidInputError
    from nnid.validation import validated

    cfg = {"vehicle": "seamor", "sequence": {}, "experiments": [{"name": "surge", "duration": 1.0}]}
    with pytest.raises(NnidInputError, match="also by a run of the sequence") as info:
        validated(SimulateConfig, cfg, "sim.toml")
    assert info.value.field == "experiments.0.name" and info.value.source == "sim.toml"


def test_open_loop_inputs_are_written_by_position_where_labels_repeat():
    """The open-loop inputs an autopilot replay regenerates, on a log of two blocks joined by
    pd.concat (labels 0..199 twice): written by label, each block's rows took both blocks'
    (a ValueError); by position, each row gets what the same log with a fresh index gets."""
    from nnid.config import load_config
    from nnid.datasets.simulator import open_loop_inputs

    cfg = load_config(ROOT / "configs/vt690_maneuvers.toml")
    name = cfg.all_experiments()[0].name
    block = pd.DataFrame({"t": 0.05 * np.arange(200), "experiment": name})
    joined = pd.concat([block, block.iloc[:150]])
    got = open_loop_inputs(cfg, joined)
    assert got.index.equals(joined.index)
    want = open_loop_inputs(cfg, joined.reset_index(drop=True))
    np.testing.assert_array_equal(got.to_numpy(), want.to_numpy())
    assert np.isfinite(want.to_numpy()).all() and want["tau_X"].abs().max() > 0
