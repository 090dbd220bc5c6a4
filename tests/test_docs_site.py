"""The documentation site builds with ``mkdocs build --strict`` (every page in the nav, every
link and anchor resolved, every docstring of the API reference parsed) and its pages render;
and what the pages show is what the code takes: every ``nnid COMMAND --option`` in their code
exists, a shipped config given to a command is one for it, and every TOML block is a config
whose keys nnid knows."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from conftest import assert_rendered

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    if shutil.which("mkdocs", path=str(Path(sys.executable).parent)) is None:
        pytest.skip('mkdocs is not installed (pip install -e ".[docs]"; .[dev] includes it)')
    out = tmp_path_factory.mktemp("site")
    done = subprocess.run(
        [str(Path(sys.executable).parent / "mkdocs"), "build", "--strict", "-d", str(out)],
        cwd=REPO,
        capture_output=True,
        text=True,
        env={"NO_MKDOCS_2_WARNING": "1", "PATH": str(Path(sys.executable).parent)},
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    return out


def test_every_nav_page_and_api_module_is_built(site):
    for page in ("index", "vehicle_file/index", "tutorials/own_rov_log/index", "api/loop/index"):
        assert (site / f"{page}.html").is_file() or (site / page).with_suffix(".html").is_file()
    api = (site / "api" / "loop" / "index.html").read_text()
    # the API page is the docstrings: the loop's class and its unexplained-structure test
    assert "ResidualLoop" in api and "unexplained_structure" in api


@pytest.mark.parametrize("page", ["api/physics/index.html", "vehicle_file/index.html"])
def test_site_pages_render(site, page, chromium, tmp_path):
    chromium(tmp_path, site / page, dump=False)
    assert_rendered(tmp_path / "s.png")


# -- what the pages say against what the code takes ----------------------------------------------
# Cheap checks (no site build, no data): a command line or a TOML block in a page, a card or a
# config's comments that the CLI or the config models would refuse is drift, caught here.

#: the pages a reader copies from; docs/loop_bluerov1/ is a run's output, not written by hand
PAGES = [
    REPO / "README.md",
    *(p for p in sorted((REPO / "docs").rglob("*.md")) if "loop_bluerov1/" not in p.as_posix()),
    *sorted((REPO / "datasets").glob("*.md")),
]
FENCE = re.compile(r"```([^\n]*)\n(.*?)```", re.S)
SPAN = re.compile(r"`([^`]+)`")
COMMAND = re.compile(r"(?<![\w./\[-])nnid\s+([a-z]\w*)((?:[ \t]+[^\s`]+)*)")


def code_texts(text: str) -> list[str]:
    """The code of a Markdown page: its fenced shell blocks and four-space indented lines
    (comments dropped) and its code spans (which may run over a line break)."""
    out = []
    for info, body in FENCE.findall(text):
        if info.strip() in ("", "bash", "text", "sh", "console") or info.startswith("bash"):
            out += [line.split(" #")[0] for line in body.replace("\\\n", " ").splitlines()]
    prose = FENCE.sub("", text)
    out += [
        line.split(" #")[0]
        for line in prose.splitlines()
        if line.startswith("    ") and "`" not in line
    ]
    out += [" ".join(span.split()) for span in SPAN.findall(prose)]
    return out


def command_lines(text: str) -> list[tuple[str, list[str], list[str]]]:
    """``(command, positional arguments, options)`` of every ``nnid COMMAND ...`` in the code
    of ``text``; each ``&&``, ``|`` or ``;`` ends one."""
    found = []
    for code in code_texts(text):
        for part in re.split(r"&&|\|\||[|;]", code):
            for m in COMMAND.finditer(part):
                words = [w.strip("[]") for w in m.group(2).split()]  # [--force]: optional
                options = [w.split("=")[0] for w in words if w.startswith("--")]
                args = []
                for before, word in zip(["", *words], words, strict=False):
                    if not word.startswith("-") and not before.startswith("--"):
                        args.append(word)
                found.append((m.group(1), args, options))
    return found


def cli_options() -> dict[str, set[str]]:
    """Each ``nnid`` command's option names, as its parser has them."""
    import typer.main

    from nnid.cli import app

    group = typer.main.get_command(app)
    return {
        name: {o for p in cmd.params for o in p.opts if o.startswith("-")} | {"--help"}
        for name, cmd in group.commands.items()
    }


def command_drift(text: str, options: dict[str, set[str]]) -> list[str]:
    """What ``text`` shows of a command or option the CLI lacks, and of a shipped config given
    to a command it is not for (the command's config model refuses it)."""
    from nnid.config import COMMANDS, load_config
    from nnid.errors import NnidInputError

    out = []
    for command, args, opts in command_lines(text):
        if command not in options:
            out.append(f"nnid {command}: no such command")
            continue
        out += [f"nnid {command} {o}: no such option" for o in opts if o not in options[command]]
        kind = "train" if command == "sweep" else command
        for arg in args:
            if kind in COMMANDS and re.fullmatch(r"configs/[\w/]+\.toml", arg):
                try:
                    load_config(REPO / arg, COMMANDS[kind])
                except NnidInputError as exc:
                    out.append(f"nnid {command} {arg}: {exc}")
    return out


def test_the_command_scan_finds_a_missing_option_and_a_config_of_another_command():
    options = cli_options()
    text = (
        "Run `nnid loop --data LOG --vehicel VEH --out DIR`, then\n\n```bash\n"
        "nnid train configs/fossen_ls.toml \\\n  --data X --out Y  # --not-an-option\n"
        "nnid compare configs/fossen_ls.toml --out cmp && nnid detect --model m --data d --out o\n"
        "```\n\n    nnid fit LOG\n\nnnid turns logs into models (prose, not a command).\n"
    )
    drift = command_drift(text, options)
    assert len(drift) == 3, drift
    assert "nnid loop --vehicel: no such option" in drift
    (wrong,) = [d for d in drift if d.startswith("nnid compare configs/fossen_ls.toml: ")]
    assert "'train' config" in wrong
    assert "nnid fit: no such command" in drift


@pytest.mark.parametrize("page", PAGES, ids=[p.relative_to(REPO).as_posix() for p in PAGES])
def test_every_command_line_shown_exists_with_its_options(page):
    assert command_drift(page.read_text(), cli_options()) == []


def test_the_commands_in_configs_comments_and_help_texts_exist_with_their_options():
    """The usage lines in the shipped configs' comments and in the CLI's own help texts."""
    import typer.main

    from nnid.cli import app

    options = cli_options()
    texts = []
    for config in sorted((REPO / "configs").rglob("*.toml")):
        comments = [line.lstrip("# ") for line in config.read_text().splitlines() if "#" in line]
        texts.append("\n".join(f"`{c.split('#', 1)[-1].strip()}`" for c in comments))
    for cmd in typer.main.get_command(app).commands.values():
        texts += [f"`{cmd.help}`"] + [f"`{p.help}`" for p in cmd.params if getattr(p, "help", 0)]
    assert [d for text in texts for d in command_drift(text, options)] == []


def block_drift(block: str, key: str | None = None) -> list[str]:
    """The keys of a TOML block from a page that its model refuses. The model is told by the
    block's keys; a block may leave out what it does not show (a member's inputs, ``...``),
    so only unknown keys and wrong values count, not missing ones. With ``key``, only what is
    refused at that key (a commented option shown alone may miss its partner: random and
    samples)."""
    import tomllib

    from pydantic import TypeAdapter, ValidationError

    from nnid.config import TrainConfig
    from nnid.datasets.column_map import ColumnMap
    from nnid.scale.manifest import Manifest
    from nnid.vehicle import Curve, Vehicle

    data = tomllib.loads(block)
    model: Any
    if "sources" in data:
        model = ColumnMap
    elif "command" in data:
        model = Manifest
    elif {"model", "sweep", "split", "data"} & set(data):
        model = TrainConfig
    elif "mass" in data:
        model = Vehicle
    elif set(data) == {"curve"}:
        model, data = Curve, data["curve"]
    else:
        return [f"a TOML block of keys {sorted(data)}: which config is it? (block_drift)"]
    try:
        TypeAdapter(model).validate_python(data)
    except ValidationError as exc:
        return [
            f"{'.'.join(map(str, e['loc']))}: {e['msg']}"
            for e in exc.errors()
            if e["type"] != "missing" and (key is None or key in e["loc"] or model is Curve)
        ]
    return []


COMMENTED = re.compile(r'^\s*#\s*(("[^"]+"|[\w.-]+)\s*=.*)$')
HEADER = re.compile(r"^\s*\[")


def commented_options(block: str) -> list[tuple[str, str]]:
    """``(block, key)`` for each option a TOML block shows commented out (``# key = value``,
    TOML on its own): the block with that line in force, in place of the same key set in its
    table (an alternative curve). A commented line that is not TOML is prose."""
    import tomllib

    lines = block.splitlines()
    out = []
    for i, line in enumerate(lines):
        m = COMMENTED.match(line)
        if m is None:
            continue
        try:
            tomllib.loads(m.group(1))
        except tomllib.TOMLDecodeError:
            continue
        raw = m.group(2)
        key = raw.strip('"') if raw.startswith('"') else raw.split(".")[-1]
        start = max((j + 1 for j in range(i) if HEADER.match(lines[j])), default=0)
        end = next((j for j in range(i + 1, len(lines)) if HEADER.match(lines[j])), len(lines))
        same = {
            j
            for j in range(start, end)
            if not lines[j].lstrip().startswith("#") and lines[j].split("=")[0].strip() == raw
        }
        shown = [m.group(1) if j == i else s for j, s in enumerate(lines) if j not in same]
        out.append(("\n".join(shown) + "\n", key))
    return out


def test_the_block_check_finds_an_unknown_key_and_a_wrong_default_type():
    assert block_drift('[model]\nkind = "narx"\nhiden = [10]\n') != []
    assert block_drift('[sweep]\ngrid = { "model.hidden" = [[3]] }\nmetrik = "x"\n') != []
    assert block_drift('curve = { kind = "poly", coefs = [1.0] }\n') != []
    # a member that leaves its inputs out is an example, not an error
    assert block_drift('[model]\nkind = "ensemble"\n[model.member]\nkind = "narx"\n') == []


@pytest.mark.parametrize("page", PAGES, ids=[p.relative_to(REPO).as_posix() for p in PAGES])
def test_every_toml_block_shown_is_a_config_nnid_takes(page):
    blocks = [body for info, body in FENCE.findall(page.read_text()) if info.strip() == "toml"]
    assert [d for block in blocks for d in block_drift(block)] == []


def test_the_block_check_reads_an_option_shown_commented_out():
    block = '[sweep]\ngrid = { "model.hidden" = [[3]] }\n# random = { "model.lr" = [1] }  # or\n'
    # random without its samples is refused at [sweep], not at the option shown: that is kept
    assert [b for b, key in commented_options(block) if block_drift(b, key)] == []
    wrong = block + "# samples = 8\n# sampels = 8  # a typo\n# seeds = [0, 1]  with a comment\n"
    found = [d for b, key in commented_options(wrong) for d in block_drift(b, key)]
    assert len(found) == 1 and found[0].startswith("sweep.sampels"), found
    thruster = '[[thrusters]]\ncurve = { kind = "poly", coeffs = [1.0] }\n'
    thruster += '# curve = { kind = "signed_quadratic", kk = 2.0 }  # or\n'
    ((alternative, key),) = commented_options("mass = 1.0\n" + thruster)
    assert key == "curve" and alternative.count("curve =") == 1
    assert block_drift(alternative, key) != []  # kk: the alternative curve is read, not skipped


@pytest.mark.parametrize("page", PAGES, ids=[p.relative_to(REPO).as_posix() for p in PAGES])
def test_every_option_a_toml_block_shows_commented_out_is_one_nnid_takes(page):
    blocks = [body for info, body in FENCE.findall(page.read_text()) if info.strip() == "toml"]
    assert [d for b in blocks for v, key in commented_options(b) for d in block_drift(v, key)] == []


def test_the_reference_names_every_option_of_every_command():
    """docs/reference.md's CLI entry (its usage lines and its list of each command's options)
    names every option the parser has, and no option a command lacks."""
    text = (REPO / "docs" / "reference.md").read_text()
    cli = text[text.index("- **CLI**") :]
    cli = cli[: cli.index("\n- **", 1)]
    options = cli_options()
    named: dict[str, set[str]] = {name: set() for name in options}
    for command, _, opts in command_lines(cli):
        named[command] |= set(opts)
    for line in re.findall(r"^\s+- (`.*?)(?=^\s+- |\Z)", cli, re.S | re.M):
        head, _, rest = line.partition(":")
        commands = re.findall(r"`(\w+)`", head)
        # "`sweep` also `--address`": what follows a command's name is its own
        for part in re.split(r"(?=`\w+` also )", rest):
            own = re.match(r"`(\w+)` also ", part)
            for command in [own.group(1)] if own else commands:
                named[command] |= set(re.findall(r"`(--[\w-]+)`", part))
    wrong = {c: sorted(named[c] - options[c]) for c in options if named[c] - options[c]}
    unsaid = {c: sorted(options[c] - named[c] - {"--help"}) for c in options}
    assert wrong == {} and {c: o for c, o in unsaid.items() if o} == {}


def test_the_reference_names_every_benchmark_script():
    text = (REPO / "docs" / "reference.md").read_text()
    scripts = sorted(p.stem for p in (REPO / "benchmarks").glob("bench_*.py"))
    assert [s for s in scripts if f"`{s}`" not in text] == []
