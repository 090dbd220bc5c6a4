"""Malformed configs (issue 12): each one is refused with exit code 2 and one line that names
the file and the key, with no traceback, before any data is loaded or simulated."""

from __future__ import annotations

import contextlib
import re
from pathlib import Path

import pytest
from conftest import SIM_STEP
from typer.testing import CliRunner

import nnid.datasets.simulator as simulator
from nnid.cli import app

ROOT = Path(__file__).resolve().parents[1]

# a second run, "b" (a sway step): the validation part
SWAY = """[[experiments]]
name = "b"
signals = [{ kind = "step", channel = "Y", amplitude = 10.0 }]
duration = 5.0
"""
SIM = SIM_STEP + SWAY

TRAIN = """kind = "train"
vehicle = "seamor"
warmup_s = 1.0
[data]
simulate = "sim.toml"
[split]
by = "experiment"
validation = ["b"]
[model]
kind = "fossen"
dofs = ["u", "v"]
unknowns = ["added_mass", "damping"]
[model.trainer]
kind = "ls"
"""

NARX = """kind = "train"
[data]
simulate = "sim.toml"
[model]
kind = "narx"
inputs = ["tau_X"]
outputs = ["u"]
[model.trainer]
kind = "lm"
"""

COMPARE = """kind = "compare"
vehicle = "seamor"
[data]
simulate = "sim.toml"
[split]
by = "experiment"
validation = ["b"]
[[models]]
kind = "synthesis"
mask = "fossen"
[[models]]
kind = "fossen"
"""

LOOP = """kind = "loop"
vehicle = "seamor"
max_effects = 2
[data]
simulate = "sim.toml"
"""

# (command, base config, (old, new) edit, key the message must name; None: the file only)
CASES = [
    ("train", TRAIN, ("unknowns =", "unknown ="), "model.unknown"),
    (
        "train",
        TRAIN,
        ('kind = "ls"', 'kind = "ls"\nfilter_lamda = 1.0'),
        "model.trainer.filter_lamda",
    ),
    ("train", TRAIN, ('kind = "fossen"', 'kind = "synthesis"\nmask = "mcfarlane"'), "model.mask"),
    ("train", TRAIN, ("warmup_s = 1.0", 'warmup_s = "one"'), "warmup_s"),
    ("train", TRAIN, ("warmup_s = 1.0", "warmup_s = -1.0"), "warmup_s"),
    ("train", TRAIN, ("warmup_s = 1.0", "warmup_s = nan"), "warmup_s"),
    ("train", TRAIN, ("warmup_s = 1.0", "k_step_s = inf"), "k_step_s"),
    (
        "train",
        TRAIN,
        ('[model.trainer]\nkind = "ls"', '[model.trainer]\nkind = "lm"'),
        "model.trainer.kind",
    ),
    (
        "train",
        NARX,
        ('[model.trainer]\nkind = "lm"', '[model.trainer]\nkind = "rls"'),
        "model.trainer.kind",
    ),
    ("train", TRAIN, ('kind = "fossen"', 'kind = "gaussian_process"'), "model.kind"),
    ("train", TRAIN, ("warmup_s = 1.0", "warmup_s = 1.0\nepochs = 3"), "epochs"),
    ("train", TRAIN, ('"added_mass", "damping"', '"X_uddot"'), "model.unknowns"),
    ("train", TRAIN, ('dofs = ["u", "v"]', 'dofs = ["u", "x"]'), "model.dofs.1"),
    ("train", TRAIN, ('simulate = "sim.toml"', 'log = "nowhere.csv"'), "data.log"),
    ("train", TRAIN, ('simulate = "sim.toml"', 'simulate = "nowhere.toml"'), "data.simulate"),
    (
        "train",
        TRAIN,
        ('simulate = "sim.toml"', 'log = "sim.toml"\ncolumns = "no.toml"'),
        "data.columns",
    ),
    ("train", TRAIN, ('kind = "train"', 'kind = "compare"'), "kind"),
    ("train", SIM, ("", ""), "kind"),
    ("train", TRAIN, ("[data]\nsimulate", '[data]\nkind = "video"\nsimulate'), "data.kind"),
    ("train", TRAIN, ('by = "experiment"', "fractions = [0.5, 0.5]"), "split.fractions"),
    ("train", NARX, ('outputs = ["u"]\n', ""), "model.outputs"),
    (
        "train",
        NARX,
        ('outputs = ["u"]', 'outputs = ["u"]\nsimulation_l2_center = "start"'),
        "model.simulation_l2_center",
    ),
    (
        "train",
        NARX,
        ('kind = "narx"', 'kind = "state_space"\nstructure = [[1, 2]]'),
        "model.structure.0.1",
    ),
    ("train", TRAIN, ('[model.trainer]\nkind = "ls"', 'trainer = "sgd"'), "model.trainer.kind"),
    ("train", TRAIN, ('dofs = ["u", "v"]', 'sequence = "weis"'), "model.sequence"),
    (
        "train",
        TRAIN,
        (
            'kind = "fossen"\ndofs = ["u", "v"]\nunknowns = ["added_mass", "damping"]\n'
            '[model.trainer]\nkind = "ls"',
            'kind = "caccia"\ndof = "z"',
        ),
        "model.dof",
    ),
    (
        "train",
        NARX,
        ('outputs = ["u"]', 'outputs = ["u"]\noutput_bounds = "maybe"'),
        "model.output_bounds",
    ),
    ("train", NARX, ('kind = "lm"', 'kind = "lm"\nmu_dec = 2.0'), "model.trainer.mu_dec"),
    (
        "train",
        NARX,
        ('kind = "lm"', 'kind = "lm"\ngeodesic = true\ngeodesic_ratio = 0'),
        "model.trainer.geodesic_ratio",
    ),
    ("train", NARX, ('kind = "lm"', 'kind = "adam"\nschedule = "step"'), "model.trainer.schedule"),
    ("train", TRAIN, ("[split]", "[split]\nvalidation = 3"), None),
    ("train", TRAIN, ("warmup_s = 1.0", "warmup_s = [1.0"), None),
    (
        "train",
        TRAIN,
        ('[data]\nsimulate = "sim.toml"', '[data]\nsimulate = "sim.toml"\nnoise = -0.1'),
        "data.noise",
    ),
    (
        "compare",
        COMPARE,
        (
            '[[models]]\nkind = "synthesis"\nmask = "fossen"\n[[models]]\nkind = "fossen"\n',
            "models = []\n",
        ),
        "models",
    ),
    ("compare", COMPARE, ('kind = "fossen"', 'kind = "synthesis"'), "models"),
    ("compare", COMPARE, ('mask = "fossen"', 'mask = "fosen"'), "models.0.mask"),
    ("compare", COMPARE, ('vehicle = "seamor"', 'vehicle = "seamor"\nk_step_s = 0.0'), "k_step_s"),
    ("compare", TRAIN, ("", ""), "kind"),
    (
        "compare",
        COMPARE,
        ('kind = "fossen"', 'kind = "fossen"\ntrainer = { kind = "adam" }'),
        "models.1.trainer.kind",
    ),
    ("loop", LOOP, ("max_effects = 2", "max_effect = 2"), "max_effect"),
    ("loop", LOOP, ("max_effects = 2", 'dofs = ["u", "z"]'), "dofs.1"),
    ("loop", TRAIN, ("", ""), "kind"),
    ("loop", LOOP, ("max_effects = 2", "alpha = 0.9"), "alpha"),
    ("loop", LOOP, ("max_effects = 2", "alpha = 1e-15"), "alpha"),  # as --alpha refuses it
    (
        "simulate",
        SIM,
        ("dt = 0.05", 'dt = 0.05\neffects = [{ name = "buoyancy_ofset", value = 1.0 }]'),
        "effects.0.name",
    ),
    (
        "simulate",
        SIM,
        ('kind = "step", channel = "X"', 'kind = "ramp", channel = "X"'),
        "experiments.0.signals.0.kind",
    ),
    ("simulate", LOOP, ("", ""), "kind"),
    ("simulate", SIM, ("dt = 0.05", "dt = 0.0"), "dt"),
]


def _args(command: str, cfg: Path, tmp_path: Path) -> list[str]:
    out = tmp_path / ("o.csv" if command == "simulate" else "out")
    if command == "loop":
        return ["loop", str(cfg), "--out", str(out)]
    return [command, str(cfg), "--out", str(out)]


@pytest.fixture
def no_simulation(monkeypatch):
    """Any simulation during these runs fails the test: configs are checked first."""

    def refuse(*args, **kwargs):
        raise AssertionError("a malformed config must be refused before any simulation")

    monkeypatch.setattr(simulator, "simulate_config", refuse)
    monkeypatch.setattr(simulator, "simulate", refuse)


@pytest.mark.parametrize(("command", "base", "edit", "key"), CASES)
def test_malformed_config_is_one_line_naming_file_and_key(
    command, base, edit, key, tmp_path, no_simulation
):
    (tmp_path / "sim.toml").write_text(SIM)
    old, new = edit
    assert old in base
    cfg = tmp_path / "bad.toml"
    cfg.write_text(base.replace(old, new, 1) if old else base)
    result = CliRunner().invoke(app, _args(command, cfg, tmp_path))
    text = result.output.strip()
    assert result.exit_code == 2, text
    assert "Traceback" not in text and text.count("\n") == 0, text
    assert text.startswith("error: ") and str(cfg) in text, text
    if key is not None:
        assert f"field '{key}'" in text, text


def test_a_config_of_the_earlier_format_says_what_replaced_the_key(tmp_path, no_simulation):
    cfg = tmp_path / "old.toml"
    cfg.write_text('model = "narx"\ntrainer = "lm"\n[narx]\ninputs = ["tau_X"]\noutputs = ["u"]\n')
    result = CliRunner().invoke(app, ["train", str(cfg), "--out", str(tmp_path / "o")])
    assert result.exit_code == 2 and "field 'narx'" in result.output
    assert 'kind = "narx"' in result.output and result.output.strip().count("\n") == 0
    # the page it points to exists and has that section (README has no "Configs" section)
    page, section = re.search(r"\(see ([^,]+), ([^)]+)\)", result.output).groups()
    assert f"## {section}\n" in (ROOT / page).read_text(), result.output


def test_there_are_at_least_25_cases():
    assert len(CASES) >= 25
    assert {c[0] for c in CASES} == {"train", "compare", "loop", "simulate"}


def test_missing_config_file_and_folder_as_config(tmp_path):
    for path in (tmp_path / "absent.toml", tmp_path):
        result = CliRunner().invoke(app, ["train", str(path), "--out", str(tmp_path / "o")])
        assert result.exit_code == 2 and str(path) in result.output
        assert result.output.strip().count("\n") == 0


def test_a_config_without_data_runs_with_data_and_vehicle_given(tmp_path):
    """'One config serves any log': a train config with no [data] section and no vehicle
    runs on --data LOG --vehicle VEH; without --data it says what to give."""
    (tmp_path / "sim.toml").write_text(SIM)
    log = tmp_path / "log.csv"
    done = CliRunner().invoke(app, ["simulate", str(tmp_path / "sim.toml"), "--out", str(log)])
    assert done.exit_code == 0, done.output
    cfg = tmp_path / "any.toml"
    cfg.write_text(
        'kind = "train"\n[split]\nby = "experiment"\nvalidation = ["b"]\n'
        '[model]\nkind = "fossen"\ndofs = ["u", "v"]\n'
    )
    # a folder name longer than a terminal line and with a bracket: the "wrote" line keeps it
    # whole (not wrapped at the console's width, "[lm]" not read as a style tag)
    out = tmp_path / ("out[lm]_" + "x" * 90)
    run = CliRunner().invoke(
        app, ["train", str(cfg), "--data", str(log), "--vehicle", "seamor", "--out", str(out)]
    )
    assert run.exit_code == 0, run.output
    assert (out / "metrics.json").exists() and (out / "model.json").exists()
    wrote = next(line for line in run.output.splitlines() if f"wrote {out}/" in line)
    # every file the run wrote is named (the cleaning report went unsaid), and only those
    listed = wrote.split(f"wrote {out}/: ")[1].split(" (")[0].split(", ")
    assert sorted(listed) == sorted(p.name for p in out.iterdir()), (listed, wrote)
    assert {"cleaning.json", "cleaning.md", "model.json", "metrics.json"} <= set(listed)
    assert "gaps" not in run.output  # a complete log: nothing filled in or left out, nothing said
    # a velocity sample missing: bridged from the pose, and the console says so (it was said
    # only in cleaning.md)
    import pandas as pd

    gappy = pd.read_csv(log)
    gappy.loc[40, "u"] = float("nan")
    gappy.to_csv(tmp_path / "gappy.csv", index=False)
    args = ["train", str(cfg), "--data", str(tmp_path / "gappy.csv"), "--vehicle", "seamor"]
    run = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "o4")])
    assert run.exit_code == 0 and "bridge velocity gaps: 1 gap in u" in run.output, run.output
    missing = CliRunner().invoke(app, ["train", str(cfg), "--out", str(tmp_path / "o2")])
    assert missing.exit_code == 2 and "field 'data'" in missing.output
    novehicle = CliRunner().invoke(
        app, ["train", str(cfg), "--data", str(log), "--out", str(tmp_path / "o3")]
    )
    assert novehicle.exit_code == 2 and "field 'vehicle'" in novehicle.output
    # the vehicle a reader config names (its documented `vehicle` key was read by nothing)
    header = [c for c in pd.read_csv(log, nrows=0).columns if c not in ("t", "experiment")]
    body = (
        'experiment = "experiment"\n[[sources]]\nfile = "log.csv"\ntime = "t"\n[sources.columns]\n'
    )
    body += "".join(f'{c} = "{c}"\n' for c in header)
    for vehicle, code in (("seamor", 0), ("nothere.toml", 2)):
        (tmp_path / "map.toml").write_text(f'vehicle = "{vehicle}"\n' + body)
        args = ["train", str(cfg), "--data", str(log), "--columns", str(tmp_path / "map.toml")]
        run = CliRunner().invoke(app, [*args, "--out", str(tmp_path / f"o5{code}")])
        assert run.exit_code == code, run.output
    assert f"{tmp_path / 'map.toml'}, field 'vehicle': 'nothere.toml'" in run.output
    # the folder a reader config's documented `root` names, when the run gives no log
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "map.toml").write_text('vehicle = "seamor"\nroot = ".."\n' + body)
    args = ["train", str(cfg), "--columns", str(tmp_path / "sub" / "map.toml")]
    run = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "o6")])
    assert run.exit_code == 0, run.output
    (tmp_path / "sub" / "map.toml").write_text('vehicle = "seamor"\n' + body)
    run = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "o7")])
    assert run.exit_code == 2 and "a reader config with a root" in run.output, run.output


def test_a_run_into_an_earlier_out_folder_leaves_no_stale_result_and_keeps_yours(tmp_path):
    """`staged`: an earlier run's monitor.json or tensors.pt that this run does not write is
    removed (detect would pair an old monitor with the new model); the user's other files
    stay; a folder of the user's where the run writes a file is refused, nothing moved."""
    from nnid.errors import NnidInputError
    from nnid.runs import staged

    out = tmp_path / "out"
    out.mkdir()
    for name in ("monitor.json", "tensors.pt", "notes.txt"):
        (out / name).write_text("earlier")
    with staged(out, supersedes=("model.json", "tensors.pt", "monitor.json")) as stage:
        (stage / "model.json").write_text("new")
    assert sorted(p.name for p in out.iterdir()) == ["model.json", "notes.txt"]
    (out / "report.md").mkdir()
    (out / "report.md" / "mine.txt").write_text("keep")
    with pytest.raises(NnidInputError, match=r"report\.md is a folder of yours"):
        with staged(out) as stage:
            (stage / "report.md").write_text("new")
            (stage / "model.json").write_text("newer")
    assert (out / "report.md" / "mine.txt").read_text() == "keep"
    assert (out / "model.json").read_text() == "new"
    assert not list(tmp_path.glob(".out-*"))  # the stage is gone


def test_a_run_that_fails_while_moving_its_files_in_leaves_the_earlier_result_whole(
    tmp_path, monkeypatch
):
    """`staged` moved a finished run's files into --out one by one: a failure after the
    first left the new model.json beside the earlier run's metrics.json. The earlier files
    are moved aside first and back on a failure: --out holds the earlier result whole (and
    the user's files), or the new one whole."""
    import os

    from nnid.errors import NnidInputError
    from nnid.runs import staged

    def contents(folder):
        return {p.name: p.read_text() for p in folder.iterdir()}

    out = tmp_path / "out"
    out.mkdir()
    earlier = {"model.json": "old", "metrics.json": "old", "monitor.json": "old"}
    for name, text in {**earlier, "notes.txt": "mine"}.items():
        (out / name).write_text(text)
    replace, into, staging = os.replace, [], []

    def failing(src, dst):
        if Path(src).parent in staging and Path(dst).parent == out:
            into.append(dst)  # a new file moved into --out
            if len(into) == 2 and failure:
                raise OSError(28, "No space left on device")
        return replace(src, dst)

    monkeypatch.setattr(os, "replace", failing)
    new = {"model.json": "new", "metrics.json": "new", "report.md": "new"}
    for failure in (True, False):
        into.clear()
        with contextlib.ExitStack() as stack:
            if failure:
                stack.enter_context(pytest.raises(NnidInputError, match="cannot be written"))
            with staged(out, supersedes=("model.json", "monitor.json")) as stage:
                staging.append(stage)
                for name, text in new.items():
                    (stage / name).write_text(text)
        if failure:
            assert len(into) == 2  # one new file was in place when the second failed
            assert contents(out) == {**earlier, "notes.txt": "mine"}
        else:
            assert contents(out) == {**new, "notes.txt": "mine"}  # monitor.json superseded


def test_an_out_folder_whose_parent_cannot_be_written_gets_its_outputs(tmp_path, monkeypatch):
    """`staged` made its stage beside --out and moved the files in: an --out that exists and
    can be written under a parent that cannot (a shared folder, a mounted volume) failed
    with PermissionError after the whole fit, a traceback. The stage is now made in --out
    itself; a folder that refuses the outputs all the same is said against --out."""
    import os

    from nnid.errors import NnidInputError
    from nnid.runs import check_out, staged

    shared = tmp_path / "shared"
    out = shared / "out"
    out.mkdir(parents=True)
    shared.chmod(0o555)
    made = os.mkdir
    refused: set[Path] = set()  # folders no stage may be made in

    def mkdir(path, *args, **kwargs):
        if Path(path).parent in refused:
            raise PermissionError(13, "Permission denied", str(path))
        return made(path, *args, **kwargs)

    try:
        if os.access(shared, os.W_OK):  # root writes it anyway: refused as for anyone else
            refused.add(shared)
            monkeypatch.setattr(os, "mkdir", mkdir)
        check_out(out)
        with staged(out) as stage:
            (stage / "report.html").write_text("new")
        assert [p.name for p in out.iterdir()] == ["report.html"]  # the stage gone
        refused.add(out)
        monkeypatch.setattr(os, "mkdir", mkdir)
        with pytest.raises(NnidInputError, match="cannot be written") as err:
            with staged(out) as stage:
                pass
        assert err.value.field == "--out" and err.value.source == str(out)
    finally:
        shared.chmod(0o755)


def test_another_packages_deprecation_notice_does_not_reach_the_user():
    """torch's forward-mode AD loads its decompositions through the deprecated
    torch.jit.script: that notice is for torch's developers and was printed to every user of
    an LM fit. nnid's own warnings, of any category, still reach them, each once."""
    import warnings

    import nnid
    from nnid.warning_messages import warning_messages

    ours = str(Path(nnid.__file__).parent / "models" / "narx.py")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        warnings.warn_explicit("`torch.jit.script` is deprecated", DeprecationWarning,
                               "/site-packages/torch/jit/_script.py", 1488)  # fmt: skip
        warnings.warn_explicit("isinstance(treespec, LeafSpec)", FutureWarning, "/x/t.py", 3)
        warnings.warn_explicit("a setting nnid retires", DeprecationWarning, ours, 1)
        for _ in range(2):
            warnings.warn_explicit("the excitation is poor", UserWarning, "/x/t.py", 3)
    assert warning_messages(caught) == ["a setting nnid retires", "the excitation is poor"]


def test_off_a_terminal_progress_is_plain_lines_every_so_often(tmp_path, monkeypatch):
    """A live bar draws nothing into a pipe or a CI log, so a long fit looked hung: there,
    plain "[N s] message" lines, none within the first HEARTBEAT_S seconds (a short run says
    nothing more than before), then at most one per HEARTBEAT_S."""
    import re

    import nnid.cli

    (tmp_path / "sim.toml").write_text(SIM)
    log = tmp_path / "log.csv"
    assert (
        CliRunner()
        .invoke(app, ["simulate", str(tmp_path / "sim.toml"), "--out", str(log)])
        .exit_code
        == 0
    )
    cfg = tmp_path / "any.toml"
    cfg.write_text('kind = "train"\n[split]\nby = "experiment"\nvalidation = ["b"]\n'
                   '[model]\nkind = "fossen"\ndofs = ["u", "v"]\n')  # fmt: skip
    args = ["train", str(cfg), "--data", str(log), "--vehicle", "seamor"]
    beat = re.compile(r"^\[\d+ s\] \S", re.M)
    # a run shorter than HEARTBEAT_S says nothing more; the bound set out of reach so that a
    # busy machine, which slows the run, cannot change what this checks
    monkeypatch.setattr(nnid.cli, "HEARTBEAT_S", 1e9)
    quiet = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "a")])
    assert quiet.exit_code == 0 and not beat.search(quiet.output), quiet.output
    monkeypatch.setattr(nnid.cli, "HEARTBEAT_S", 0.0)
    said = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "b")])
    assert said.exit_code == 0 and beat.search(said.output), said.output


def test_a_config_of_no_kind_nnid_has_names_the_kinds(tmp_path, no_simulation):
    """kind = "detect" is not a config kind (detection is a train config with [detect]); the
    message said "for another tool"."""
    (tmp_path / "sim.toml").write_text(SIM)
    cfg = tmp_path / "det.toml"
    cfg.write_text(TRAIN.replace('kind = "train"', 'kind = "detect"', 1))
    text = CliRunner().invoke(app, _args("train", cfg, tmp_path)).output
    assert "'detect' is not a config kind (kinds: " in text and "train" in text, text
    assert "a 'train' config with a [detect] table" in text and "another tool" not in text


def test_a_sweep_of_another_kind_of_config_names_the_command_that_was_run(tmp_path):
    """`nnid sweep` on a compare config said "`nnid train` needs a 'train' config": the user
    ran sweep."""
    cfg = tmp_path / "cmp.toml"
    cfg.write_text('kind = "compare"\n')
    run = CliRunner().invoke(app, ["sweep", str(cfg), "--out", str(tmp_path / "o")])
    assert run.exit_code == 2, run.output
    text = " ".join(run.output.split())
    assert "`nnid sweep` needs a 'train' config" in text and "nnid train`" not in text, text


def test_a_config_naming_its_runs_on_another_log_says_what_that_log_holds(tmp_path):
    """The shipped Seamor comparison with --data the demo log: refused naming the runs it wants
    but not the ones the log has, nor the way to run it there."""
    demo = ROOT / "nnid/demo_data"
    run = CliRunner().invoke(app, ["compare", str(ROOT / "configs/seamor_families.toml"),
                                   "--data", str(demo / "demo_minirov_heave.parquet"),
                                   "--vehicle", str(demo / "minirov.toml"),
                                   "--out", str(tmp_path / "o")])  # fmt: skip
    assert run.exit_code == 2, run.output
    text = " ".join(run.output.split())
    assert "are not in the log (it has [" in text and "name its runs in data.experiments" in text
    assert not (tmp_path / "o").exists()


def test_python_dash_m_runs_the_command_line():
    """`python -m nnid` had no entry, and `python -m nnid.cli` ran nothing and exited 0."""
    import subprocess
    import sys

    for module in ("nnid", "nnid.cli"):
        done = subprocess.run([sys.executable, "-m", module, "--version"], capture_output=True,
                              text=True, timeout=120)  # fmt: skip
        assert done.returncode == 0 and done.stdout.startswith("nnid "), (module, done)


def test_a_validation_score_that_stopped_the_training_is_said_so_when_shown(tmp_path):
    """With no test part the console line shows the validation score, which early stopping
    used: it says so, and so does the batch table's "held out" cell (the reports did)."""
    from nnid.reports.batch_report import _held_out

    sim = SIM.replace('channel = "Y"', 'channel = "X"')  # both runs surge
    (tmp_path / "sim.toml").write_text(sim)
    cfg = tmp_path / "narx.toml"
    cfg.write_text(NARX.replace('kind = "lm"', 'kind = "adam"\nmax_epochs = 2')
                   + '[split]\nby = "experiment"\nvalidation = ["b"]\n')  # fmt: skip
    run = CliRunner().invoke(app, _args("train", cfg, tmp_path))
    assert run.exit_code == 0, run.output
    assert "validation free-run NRMSE total" in run.output
    assert "used for early stopping while fitting" in " ".join(run.output.split()), run.output
    row = {"held_out": "validation", "validation_used_for": "early stopping"}
    assert _held_out(row) == "validation (used for early stopping)"
    assert _held_out({**row, "held_out": "test"}) == "test"


@pytest.mark.parametrize("command", ["train", "compare"])
def test_a_k_step_horizon_longer_than_every_held_out_run_says_why_it_was_not_scored(
    tmp_path, command
):
    """k_step_s = 8 s on 5-s runs: no k-step prediction is left to score, and the report says
    "not scored"; the console now says why (no run is long enough) and what would score it."""
    import json

    (tmp_path / "sim.toml").write_text(SIM)
    cfg = tmp_path / "long_k.toml"
    base = TRAIN if command == "train" else COMPARE
    cfg.write_text(base.replace('vehicle = "seamor"', 'vehicle = "seamor"\nk_step_s = 8.0', 1))
    run = CliRunner().invoke(app, _args(command, cfg, tmp_path))
    assert run.exit_code == 0, run.output
    said = " ".join(run.output.split())
    assert "k_step_s = 8 s: no validation run is long enough" in said, said
    assert "(the longest has 101 samples" in said and "k-step error was not scored" in said
    if command == "train":
        metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
        assert metrics["validation"]["k_step_scored"] == 0
        assert any("k_step_s = 8 s" in w for w in metrics["warnings"])
    else:  # each model's warnings (compare kept them to the JSON), this one among them
        comparison = json.loads((tmp_path / "out" / "comparison.json").read_text())
        own = [f"{m['name']}: {w}" for m in comparison["models"] for w in m["warnings"]]
        assert any("k_step_s = 8 s" in w for w in own)
        report = (tmp_path / "out" / "report.md").read_text().split("## Warnings")[1]
        for line in [*comparison["warnings"], *own]:
            assert f"- {line}" in report and " ".join(line.split()) in said
    # the horizon it advises scores: the longest run's samples past the model's own warm-up
    advised = float(re.search(r"a k_step_s of at most ([\d.]+) s", said).group(1))
    cfg.write_text(
        base.replace('vehicle = "seamor"', f'vehicle = "seamor"\nk_step_s = {advised}', 1)
    )
    again = [*_args(command, cfg, tmp_path)[:-1], str(tmp_path / "again")]
    run = CliRunner().invoke(app, again)
    assert run.exit_code == 0 and "k_step_s" not in run.output, run.output
    if command == "train":
        metrics = json.loads((tmp_path / "again" / "metrics.json").read_text())
        assert metrics["validation"]["k_step_scored"] > 0


def test_a_run_in_no_part_of_a_named_split_is_said_and_noise_on_no_column_refused(tmp_path):
    """split.train names run a, validation b: run c was used nowhere and said nowhere. And
    noise_columns naming a column the log lacks added noise to nothing, while the cleaning
    report said it was added."""
    import json

    third = "[[experiments]]" + SIM.split("[[experiments]]")[2].replace('"b"', '"c"')
    (tmp_path / "sim.toml").write_text(SIM + third)
    cfg = tmp_path / "named.toml"
    cfg.write_text(TRAIN.replace('validation = ["b"]', 'train = ["a"]\nvalidation = ["b"]'))
    run = CliRunner().invoke(app, _args("train", cfg, tmp_path))
    assert run.exit_code == 0, run.output
    assert "experiments c are in no part of the split" in " ".join(run.output.split())
    report = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert report["split"]["parts"]["train"][0]["experiment"] == "a"
    cfg.write_text(TRAIN.replace("[data]\n", "[data]\nnoise = 0.1\n"))  # the default columns
    run = CliRunner().invoke(app, [*_args("train", cfg, tmp_path)[:-1], str(tmp_path / "d")])
    assert (
        run.exit_code == 0 and "white noise of 0.1" in (tmp_path / "d" / "cleaning.md").read_text()
    )
    cfg.write_text(TRAIN.replace("[data]\n", '[data]\nnoise = 0.1\nnoise_columns = ["uu"]\n'))
    run = CliRunner().invoke(app, [*_args("train", cfg, tmp_path)[:-1], str(tmp_path / "n")])
    assert run.exit_code == 2 and "data.noise_columns" in run.output, run.output
    assert "noise_columns names uu, which the log does not have" in " ".join(run.output.split())
    cfg.write_text(
        TRAIN.replace('validation = ["b"]', 'validation = ["b"]\nfractions = [0.5, 0.5, 0]')
    )
    run = CliRunner().invoke(app, [*_args("train", cfg, tmp_path)[:-1], str(tmp_path / "f")])
    assert run.exit_code == 2 and "split.fractions" in run.output, run.output


def test_a_compared_model_whose_training_diverged_is_said(tmp_path, monkeypatch):
    """train said it (a warning in metrics.json); compare ranked such a model with no word.
    The NARX's one-step stage is recorded as ended on a non-finite loss (Adam's normalised
    steps keep this small net finite, so the record stands in for a diverged fit)."""
    import json

    from nnid.models.narx import NarxModel

    described = NarxModel.describe

    def diverged(self):
        out = described(self)
        out["history"] = {**out["history"], "stop_reason": "non-finite loss"}
        return out

    monkeypatch.setattr(NarxModel, "describe", diverged)
    (tmp_path / "sim.toml").write_text(SIM)
    cfg = tmp_path / "cmp.toml"
    cfg.write_text(
        'kind = "compare"\n[data]\nsimulate = "sim.toml"\n[split]\nby = "experiment"\n'
        'validation = ["b"]\n[[models]]\nkind = "narx"\nname = "wild"\ninputs = ["tau_X"]\n'
        'outputs = ["u"]\ntrainer = { kind = "adam", max_epochs = 3 }\n'
    )
    run = CliRunner().invoke(app, _args("compare", cfg, tmp_path))
    assert run.exit_code == 0, run.output
    comparison = json.loads((tmp_path / "out" / "comparison.json").read_text())
    (wild,) = comparison["models"]
    assert any(w.startswith("training diverged in") for w in wild["warnings"]), wild["warnings"]
    assert "wild: training diverged in" in " ".join(run.output.split())


def test_a_free_run_above_one_is_said_to_have_no_skill():
    """BlueROV1's least-squares fit scored its held-out runs 1.02 (validation 1.24) with no
    warning: a free-run NRMSE above 1 simulates the data no better than their mean."""
    from nnid.pipeline import without_skill

    (said,) = without_skill("test", {"free_run_nrmse": {"u": 1.3, "total": 1.02}})
    assert said.startswith("the test free-run NRMSE is 1.02, above 1")
    assert without_skill("test", {"free_run_nrmse": {"total": 0.98}}) == []
    assert without_skill("test", {"free_run_nrmse": {"total": None}}) == []  # diverged: said
    assert without_skill("validation", {}) == []  # elsewhere, not as this


@pytest.mark.parametrize(("setting", "expected"), [("filter_lambda = 0", None), ("", 1.0)])
def test_a_loop_config_switches_the_regressor_filter_off_with_filter_lambda_zero(
    tmp_path, setting, expected
):
    """The loop filters its regressors by default (λ = 1 rad/s) and TOML has no null: the
    filter could not be switched off from a config (0 was refused as not above 0)."""
    import json
    from importlib import resources

    demo = resources.files("nnid.demo_data")
    config = tmp_path / "loop.toml"
    config.write_text(f'kind = "loop"\nmax_effects = 0\n{setting}\n')
    args = ["loop", str(config), "--data", str(demo.joinpath("demo_minirov_heave.parquet"))]
    args += ["--vehicle", str(demo.joinpath("minirov.toml")), "--out", str(tmp_path / "o")]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    loop = json.loads((tmp_path / "o" / "loop.json").read_text())
    assert loop["settings"]["filter_lambda"] == expected


def test_a_log_whose_stamps_come_in_bursts_is_refused_by_train_and_loop_naming_its_run(tmp_path):
    """A run whose stamps come in bursts (five samples 10 µs apart, every 0.25 s), logged with
    its velocities and accelerations, so no derivative refuses it: a model steps by its run's
    median step, one inside a burst. The loop fitted it and ran to its end (a run all in
    bursts gave findings at lags of 1e-05 s) and train refused it as samples missing; both
    refuse it, before any fit, by the bursts' rule, naming the run (run0 before it, on a
    regular clock, passes)."""
    from importlib import resources

    import numpy as np
    import pandas as pd

    demo = resources.files("nnid.demo_data")
    log = pd.read_parquet(demo.joinpath("demo_minirov_heave.parquet"))
    log = log[log["experiment"].isin(["run0", "run1", "run2"])].groupby("experiment").head(300)
    log = log.reset_index(drop=True)
    for c in ("u", "v", "w", "p", "q", "r"):
        log["d" + c] = np.gradient(log[c].to_numpy(), log["t"].to_numpy())
    k = np.arange(300)
    log.loc[log["experiment"] == "run1", "t"] = 0.25 * (k // 5) + 1e-5 * (k % 5)
    data = tmp_path / "imu.csv"
    log.to_csv(data, index=False)
    vehicle = str(demo.joinpath("minirov.toml"))
    for command in (["train", str(ROOT / "configs/fossen_ls.toml")], ["loop"]):
        args = [*command, "--data", str(data), "--vehicle", vehicle]
        run = CliRunner().invoke(app, [*args, "--out", str(tmp_path / command[0])])
        assert run.exit_code == 2, run.output
        text = " ".join(run.output.split())
        assert "Traceback" not in text and text.count("error:") == 1, text
        assert f"{data}, field 't': experiment 'run1': its stamps come in bursts" in text, text
        assert not (tmp_path / command[0]).exists()


def test_metrics_json_records_the_k_step_horizon_that_was_scored(tmp_path):
    """k_step_s = 0.13 s at 20 Hz is 2.6 samples: 3 were scored, 0.15 s ahead, and
    metrics.json kept 0.13 s alone, a horizon nothing was scored at (0.25 s at 10 Hz rounds
    to 2 samples, 0.2 s). It keeps the asked value and says the samples scored and, per
    part, that horizon in the part's own seconds."""
    from nnid.config import TrainConfig, load_config
    from nnid.pipeline import run_train

    (tmp_path / "sim.toml").write_text(SIM)
    cfg = tmp_path / "k.toml"
    cfg.write_text(TRAIN.replace('vehicle = "seamor"', 'vehicle = "seamor"\nk_step_s = 0.13', 1))
    metrics = run_train(load_config(cfg, TrainConfig), cfg).metrics
    assert metrics["k_step_s"] == 0.13 and metrics["k_step_samples"] == 3
    for part in ("train", "validation"):
        assert metrics[part]["k_step"] == 3
        assert metrics[part]["k_step_s"] == pytest.approx(3 * 0.05, rel=1e-9)
