from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image
from threadpoolctl import threadpool_limits

from nnid.vehicle import vehicle_from_dict

#: a simulate config of one 5 s surge step ("a") on the seamor preset: the config tests'
#: simulation, which a test extends with its own experiments or keys
SIM_STEP = """kind = "simulate"
vehicle = "seamor"
dt = 0.05
[[experiments]]
name = "a"
signals = [{ kind = "step", channel = "X", amplitude = 10.0 }]
duration = 5.0
"""


def load_script(path: Path, monkeypatch: pytest.MonkeyPatch):
    """A script file (a benchmark, a docs example) as a module. Its ``sys.modules`` entry (its
    dataclasses look their module up there) and the ``sys.path`` entries it adds (its lazy
    imports of sibling scripts need them) last until ``monkeypatch`` is undone, so a test
    leaves no trace in the process."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setattr(sys, "path", list(sys.path))
    monkeypatch.setitem(sys.modules, path.stem, module)
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


def make_vehicle(**overrides):
    """A small neutral test vehicle (not a preset); keyword arguments replace fields."""
    data = dict(
        name="testbox",
        mass=30.0,
        inertia=[1.2, 2.5, 2.8],
        added_mass={
            "X_udot": -10.0,
            "Y_vdot": -25.0,
            "Z_wdot": -30.0,
            "K_pdot": -0.8,
            "M_qdot": -1.5,
            "N_rdot": -1.2,
        },
        damping={"model": None, "coefficients": {}},
    )
    data.update(overrides)
    return vehicle_from_dict(data)


@pytest.fixture
def vehicle_factory():
    return make_vehicle


torch.set_default_dtype(torch.float64)


def _chromium(tmp_path: Path, page: Path, dump: bool) -> subprocess.CompletedProcess:
    """Headless Chromium on a report page: its DOM after scripts ran (``dump``), or a
    1200 × 2400 screenshot ``tmp_path/s.png``. Skips where Chromium is not installed."""
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        pytest.skip("Chromium is not installed (Debian package 'chromium'; .ci/run installs it)")
    cmd = [
        browser,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        f"--user-data-dir={tmp_path / 'profile'}",
        "--virtual-time-budget=5000",
        *(
            ["--dump-dom"]
            if dump
            else ["--window-size=1200,2400", f"--screenshot={tmp_path}/s.png"]
        ),
        page.as_uri(),
    ]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    return done


@pytest.fixture
def chromium():
    """:func:`_chromium`: render a report page in headless Chromium."""
    return _chromium


def assert_rendered(screenshot: Path) -> None:
    """A :func:`_chromium` screenshot shows a page, not a blank one: text and plot lines make
    dark pixels in many rows."""
    shot = np.asarray(Image.open(screenshot).convert("L"), dtype=float)
    assert shot.shape == (2400, 1200)
    dark_rows = (shot < 100).any(axis=1).mean()
    assert dark_rows > 0.3, dark_rows


def assert_labels_inside(fig) -> None:
    """A report figure of fixed margins (no layout engine): every shown panel's tick labels,
    axis labels, title and legend lie inside the figure and out of the other panels."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    assert fig.get_layout_engine() is None  # the fixed margins, not the constrained layout
    renderer = FigureCanvasAgg(fig).get_renderer()
    page = fig.bbox
    shown = [ax for ax in fig.axes if ax.get_visible()]
    boxes = [ax.get_tightbbox(renderer) for ax in shown]
    for ax, box in zip(shown, boxes, strict=True):
        assert box.x0 >= page.x0 and box.x1 <= page.x1, (ax.get_ylabel(), box, page)
        assert box.y0 >= page.y0 and box.y1 <= page.y1, (ax.get_title(), box, page)
    panels = [ax.get_window_extent(renderer) for ax in shown]
    for i, box in enumerate(boxes):  # a panel's labels never reach into another panel
        for j, panel in enumerate(panels):
            assert i == j or not box.overlaps(panel), (i, j)


@pytest.hookimpl(tryfirst=True)  # before xdist reads the groups into the node ids
def pytest_collection_modifyitems(config, items):
    """Under pytest-xdist's ``--dist loadgroup`` (the README's test command), keep each test
    module on one worker, so that its module-scoped fixtures (a fitted comparison, a trained
    hybrid) are computed once; a test that names its own ``xdist_group`` (the hybrid's
    scenarios, one group per simulated log) is placed by that group instead."""
    for item in items:
        if item.get_closest_marker("xdist_group") is None:
            item.add_marker(pytest.mark.xdist_group(item.module.__name__))
    # longest groups first: xdist hands groups out in collection order, so a long group
    # collected last runs alone at the end while the other worker idles
    items.sort(
        key=lambda item: -GROUP_SECONDS.get(item.get_closest_marker("xdist_group").args[0], 0)
    )


#: seconds each long test group takes on one worker of the 2-core CI machine (measured
#: 2026-12-01, the mean of two idle fresh-clone CI runs' junit times under -n 2: test_fault
#: had grown from 36 to 88 s and test_bad_input_corpus from 22 to 46 s, so both were handed
#: out after groups a third their length; a group not named here is short); only the order
#: matters, not the values
GROUP_SECONDS = {
    "test_scale": 132,
    "test_loop": 125,
    "test_fault": 88,
    "test_compare": 71,
    "test_tutorials": 47,
    "test_bad_input_corpus": 46,
    "test_ensemble": 36,
    "test_hybrid": 32,
    "test_sindy": 30,
    "hybrid-thruster_installation.w.neg": 25,
    "test_parametric": 24,
    "hybrid-actuator_lag": 23,
    "test_narx": 22,
    "hybrid-coupled_damping.N:u*v": 22,
    "test_real_datasets": 19,
    "test_neural_state_space": 14,
    "hybrid-current.y": 14,
    "test_protocol": 11,
    "test_bluerov1_real": 10,
    # 2026-12-01: a 120-s log each (were 14 and 7), scaled from a local run to the CI's
    "hybrid-external_bias.u": 4,
    "hybrid-none": 3,
}


def pytest_configure(config):
    """Under pytest-xdist, one thread per worker for numba, torch and BLAS: two workers on two
    cores with two threads each would oversubscribe them (busy-waiting OpenMP and BLAS
    threads; a comparison that takes 31 s with one numba thread beside a busy core took 36 s
    with two, 2026-11-28). Numba first: starting its OpenMP layer resets the count torch
    reads. A test setting, never the library's: nnid itself leaves process-wide thread counts
    alone (a test that needs numba's threads asks for them: :func:`all_numba_threads`)."""
    if os.environ.get("PYTEST_XDIST_WORKER"):
        import numba

        numba.set_num_threads(1)
        torch.set_num_threads(1)
        threadpool_limits(1)


def pytest_sessionstart(session):
    """In pytest-xdist's controller, before its workers start (xdist starts them in its own
    sessionstart, run last): nnid's numba kernels compiled into their on-disk cache once, in
    one process per core (:mod:`kernel_warmup`), so that the workers, and the processes their
    tests start, load them instead of each compiling the same ones (a fresh clone, as CI
    runs). Only the time changes; a failure here is said and costs only that time."""
    config = session.config
    if not config.pluginmanager.has_plugin("dsession"):
        return  # one process, --collect-only or a worker: kernels compile where first called
    if os.environ.get("NUMBA_DISABLE_JIT", "0") not in ("", "0"):
        return  # nothing is compiled (a coverage run)
    if os.environ.get("NNID_KERNEL_WARMUP", "1") == "0":
        return  # asked not to (timing the suite without it)
    from kernel_warmup import warm

    seconds, failed = warm(min(len(config.getoption("tx")), os.cpu_count() or 1))
    reporter = config.pluginmanager.get_plugin("terminalreporter")
    for line in failed if reporter is not None else []:
        reporter.write_line(f"numba kernel warm-up failed ({seconds:.0f} s): {line}")


@pytest.fixture
def all_numba_threads():
    """Every numba thread the machine has for the test (the xdist workers run with one), so
    that a parallel kernel really runs in threads; restored afterwards."""
    import numba

    from nnid.threads import numba_threads

    with numba_threads(numba.config.NUMBA_NUM_THREADS):
        yield numba.get_num_threads()


#: the process helpers below read /proc
needs_proc = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc (Linux)")


def child_pids(pid: int) -> list[int]:
    """The pids whose parent is ``pid`` (Linux /proc)."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:  # the process ended while the folder was read
            continue
        if int(fields[1]) == pid:
            found.append(int(stat.parent.name))
    return found


def cmdline(pid: int) -> str:
    """The command line of ``pid`` ("" once it has ended)."""
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


def is_alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie has ended)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def stop_cli(
    args: list[str], workers_of: Callable[[int], list[int]], stderr: Path
) -> tuple[int, list[int]]:
    """Run ``nnid *args`` through the console entry in a subprocess; once ``workers_of(pid)``
    names the worker processes to watch, let it work 2 s and send it SIGTERM. Returns its exit
    code and the workers still alive 30 s after it ended (every process it left is killed
    afterwards)."""
    cmd = [sys.executable, "-c", "from nnid.cli import main; main()", *args]
    with stderr.open("w") as sink:
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=sink)
    workers: list[int] = []
    try:
        deadline = time.monotonic() + 240
        while not workers and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.05)
            workers = workers_of(proc.pid)
        assert proc.poll() is None and workers, stderr.read_text()
        time.sleep(2.0)  # into the work
        proc.send_signal(signal.SIGTERM)
        code = proc.wait(timeout=120)
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and any(is_alive(p) for p in workers):
            time.sleep(0.5)
        return code, [p for p in workers if is_alive(p)]
    finally:
        for pid in [proc.pid, *workers]:
            if is_alive(pid):
                os.kill(pid, signal.SIGKILL)
