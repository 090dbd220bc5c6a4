"""Peers in the same run: SysIdentPy FROLS and NARXNN beside nnid's NARX and neural state-space
model, on Cascaded Tanks, Silverbox and the Seamor four-output case.

Needs the ``bench`` extra (``pip install -e '.[bench]'``: ``sysidentpy``, ``nonlinear-benchmarks``;
torch stays the project's). Measured per case and model: the free-run test error, the
validation error where there is one, the time to fit (wall clock; run with
``OMP_NUM_THREADS=1`` for one-thread timings; an ensemble's is all its members' fits, their
median in a column of its own) and the peak resident memory the fit added
(``VmHWM`` after resetting it through ``/proc/self/clear_refs``, minus the resident memory
before; Linux only, else blank; for the nlbench nnid rows it spans ``bench_nlbench.run``, fit
and scoring).

Data, splits and warm-ups.

- ``cascaded_tanks``, ``silverbox``: the data are read offline from ``../shared/data/nlbench-*``
  by :func:`nnid.datasets.benchmarks.load_benchmark`. ``nonlinear-benchmarks`` (1.0.1)
  downloads its data when its loaders are called, and this machine has no internet: its
  loaders are run on the same shared files instead (:func:`official_splits`: the CSV records
  written as the ``.mat`` files the loaders read, plus an empty stand-in for the downloaded
  zip, in a temporary folder passed as ``dir_placement``, so nothing is fetched). The script
  checks that its splits equal nnid's sample for sample and that its warm-up
  (``state_initialization_window_length``) equals nnid's ``Benchmark.warmup`` (from the
  folders' ``SOURCE.md``), and stops if not: 50 samples for both cases (``nonlinear-benchmarks``
  1.0.0 had 5 for the tanks, 1.0.1 has 50). The scores use its ``error_metrics.RMSE`` with
  ``n_init`` = that warm-up; a free run that diverged by nnid's rule (:func:`common.
  scored_free_run`, which scores nnid's rows) scores None. Train = the estimation split; tests
  = ``test`` (tanks), ``test_multisine`` and ``test_arrow_full`` (silverbox), as in
  ``benchmarks/bench_nlbench.py``.
  Score = free-run RMSE over the samples after the warm-up, in V (tanks) or mV (silverbox); the
  delay states are the measured outputs of the first ``max_lag`` samples, inside the warm-up.
- ``seamor``: the data of ``configs/seamor_narx_lm.toml`` exactly as ``nnid train`` builds them
  (:func:`nnid.pipeline.load_inputs`, :func:`nnid.pipeline.make_split`: the simulated Seamor runs
  with 1 % noise, split by experiment into the config's test run, validation runs and training runs;
  the run names are printed and saved with the rows). Inputs tau_X tau_Y tau_Z tau_N, outputs u v w
  r. Score = free-run NRMSE per output (RMSE / std of the measured output,
  :func:`nnid.evaluation.evaluate.score_split`, the function behind ``metrics.json``, which also
  scores each run alone and calls a pooled column diverged where one run's did) over the
  samples after the config's ``warmup_s`` (1 s, nnid's; ``nonlinear-benchmarks`` has no such case),
  on the columns ``nnid train`` scores (:func:`nnid.datasets.preprocess.excited_dofs`: w only where
  the run excites it); ``total`` = their mean. SysIdentPy is single-output: one model per output,
  its regressors the four inputs and the three other outputs (lagged); the four are simulated
  jointly (:class:`CoSimulation`: at each step every model's prediction uses the others' simulated
  outputs). Each run checks the co-simulation against SysIdentPy's ``model.predict`` with the other
  outputs fed measured (``cosim_check``: the largest difference over the std of the output plus the
  size of the prediction, so that a diverging run is compared relatively), and stops where it
  exceeds :data:`COSIM_TOLERANCE` (1e-3; FROLS's read 1e-14). SysIdentPy takes one
  record: the training runs are concatenated, so the ``max_lag`` rows after each junction (≤ 4 × 21
  of 147,622 with the current config's 22 training runs) have lagged values from the end of the
  previous run (each run starts at rest).

Selection. No setting sees the test data. FROLS: a small grid (:data:`FROLS_GRID`, least
squares; polynomial degree, lags, model size by AIC or by ``err_tol``) scored on a validation
part: the tail of the training split for the nlbench cases (tanks: train on samples 0-767,
validate on 718-1023 (50 warm-up), the tail fold of ``bench_nlbench.py --holdout``; silverbox:
train on the first 80 %, validate on the rest with the 50 samples before it as warm-up), the
config's validation runs for Seamor (each run a free run from its own measured start). The
setting with the lowest validation error (a diverged free run never wins) is refitted on the
whole training split (nlbench; for Seamor the validation fit is the model) and scored on the
test splits. The Silverbox settings of
SysIdentPy's book (Case Studies, "Silver box", current version, which scores as here: after the
loader's 50-sample window, the delay states taken inside it; degree 2, lags 7, ``err_tol``
0.999, 40 terms → 7.727 mV on the multisine test; degree 3, lags 14, ``err_tol`` 0.9999, 80 /
40 terms → 4.148 mV on the full arrow / 2.229 mV on the arrow without extrapolation), fitted
there on the whole training split, are in the grid and also scored on the test splits, marked
``book``. A setting whose estimated memory (:data:`MEMORY_FACTOR`) exceeds ``--max-gb``
(default 10 GB) is skipped and said so; the degree-3, lag-14 ones are estimated at 9.8 GB on
the 65,062 training samples. NARXNN: standardised data (training mean and std), one tanh
hidden layer, SysIdentPy's own training loop (Adam, lr 0.01, batches of 100 in order), a few
seeds; the setting with the lowest median validation error over the seeds is chosen, and its
test error is the median over the seeds (each seed in the JSON). NARXNN 0.9.0's constructor
takes only an int per input in ``xlag``, which SysIdentPy reads as that one lag when it builds
the regressors but as lags 1..n when it names them; the nested lists its fit and predict
accept are set after construction (:func:`make_narxnn`).

nnid: :func:`nnid_rows`, the NARX and the neural state-space model as
``benchmarks/bench_nlbench.py`` sets them for the nlbench cases (its ``SETTINGS`` and
``run``; the test error of several seeds is their ensemble where the setting has one, else
the median); for Seamor the NARX of ``configs/seamor_narx_lm.toml`` and of
``configs/seamor_narx_adam.toml`` fitted through the library as ``nnid train`` does
(:data:`SEAMOR_NNID_CONFIGS`; a state-space config can be added there):
once per seed for a single-net config, once for an ensemble config (its own seeds).

Run: ``python benchmarks/bench_peers.py [cascaded_tanks silverbox seamor] [--seeds 0,1,2]
[--quick] [--only sysidentpy|nnid] [--max-gb 10] [--json PATH]`` (``--quick``: two FROLS
settings, one NARXNN setting with few epochs, one nnid seed: a smoke run).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass, field
from datetime import date
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import ensemble_free_run, machine, scored_free_run

from nnid.datasets.benchmarks import load_benchmark

REPO = Path(__file__).resolve().parents[1]
ROOT = REPO.parent / "shared" / "data"
SEAMOR_CONFIG = REPO / "configs" / "seamor_narx_lm.toml"
CASES = ("cascaded_tanks", "silverbox", "seamor")

#: per nlbench case: the test splits, the unit scale and name, the validation cut
NLBENCH = {
    "cascaded_tanks": {"tests": ["test"], "scale": 1.0, "unit": "V", "holdout": 768},
    "silverbox": {
        "tests": ["test_multisine", "test_arrow_full"],
        "scale": 1e3,
        "unit": "mV",
        "holdout": 0.8,  # fraction of the training split the selection fit sees
    },
}

# -- FROLS and NARXNN settings --------------------------------------------------------------------
# A FROLS setting: polynomial degree, lag (ylag = xlag = 1..lag for every input), and either
# order selection by an information criterion over n_info_values terms or err_tol with at most
# n_terms terms (SysIdentPy's book's choice for long records). Estimator: least squares (the
# 0.9.0 default is recursive least squares; the book uses LeastSquares()).
AIC = {"order_selection": True, "info_criteria": "aic"}
FROLS_GRID: dict[str, list[dict]] = {
    "cascaded_tanks": [
        {"degree": 1, "lag": 2, **AIC, "n_info_values": 10},
        {"degree": 1, "lag": 4, **AIC, "n_info_values": 10},
        {"degree": 2, "lag": 2, **AIC, "n_info_values": 20},
        {"degree": 2, "lag": 4, **AIC, "n_info_values": 30},
        {"degree": 3, "lag": 2, **AIC, "n_info_values": 30},
        {"degree": 3, "lag": 3, **AIC, "n_info_values": 30},
    ],
    "silverbox": [
        {"degree": 2, "lag": 4, **AIC, "n_info_values": 20},
        {"degree": 2, "lag": 7, "err_tol": 0.999, "n_terms": 40, "book": "multisine"},
        {"degree": 3, "lag": 4, "err_tol": 0.9999, "n_terms": 40},
        {"degree": 3, "lag": 7, "err_tol": 0.9999, "n_terms": 40},
        {"degree": 3, "lag": 14, "err_tol": 0.9999, "n_terms": 80, "book": "arrow full"},
        {"degree": 3, "lag": 14, "err_tol": 0.9999, "n_terms": 40, "book": "arrow no extrap."},
    ],
    # order selection reruns the ERR for every model size: 160 s for degree 2 here, so the
    # nonlinear settings use err_tol (one pass)
    "seamor": [
        {"degree": 1, "lag": 2, **AIC, "n_info_values": 30},
        {"degree": 1, "lag": 4, **AIC, "n_info_values": 30},
        {"degree": 2, "lag": 2, "err_tol": 0.9999, "n_terms": 15},
        {"degree": 2, "lag": 2, "err_tol": 0.9999, "n_terms": 40},
        {"degree": 2, "lag": 4, "err_tol": 0.9999, "n_terms": 40},
        {"degree": 3, "lag": 2, "err_tol": 0.9999, "n_terms": 40},
    ],
}
#: the settings of ``--quick`` (a smoke run): indexes into FROLS_GRID
FROLS_QUICK = {"cascaded_tanks": [0, 2], "silverbox": [1, 2], "seamor": [0, 2]}

#: NARXNN: lag (ylag = xlag), hidden tanh units, epochs (SysIdentPy's default is 200; fewer on the
#: long records so that one fit stays near a minute on one thread)
NARXNN_GRID: dict[str, list[dict]] = {
    "cascaded_tanks": [
        {"lag": 2, "hidden": 10, "epochs": 200},
        {"lag": 4, "hidden": 10, "epochs": 200},
    ],
    "silverbox": [{"lag": 4, "hidden": 10, "epochs": 10}, {"lag": 7, "hidden": 10, "epochs": 10}],
    "seamor": [{"lag": 2, "hidden": 10, "epochs": 10}, {"lag": 4, "hidden": 10, "epochs": 10}],
}
NARXNN_QUICK_EPOCHS = {"cascaded_tanks": 50, "silverbox": 2, "seamor": 2}
NARXNN_SEEDS = (0, 1, 2)

#: FROLS working memory ≈ this × the candidate matrix (rows × candidates × 8 bytes): measured
#: with VmHWM on silverbox (4.1 with err_tol, 5.9 with order selection)
MEMORY_FACTOR = {"err_tol": 4.2, "order_selection": 6.0}


# -- memory --------------------------------------------------------------------------------------


def _status_mb(key: str) -> float | None:
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith(key + ":"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return None


class PeakMemory:
    """The peak resident memory a block adds: VmHWM (reset on entry through
    ``/proc/self/clear_refs``) minus VmRSS on entry, in MB; ``mb`` is None where that is not
    available."""

    def __enter__(self) -> PeakMemory:
        self.mb: float | None = None
        try:
            with open("/proc/self/clear_refs", "w") as fh:
                fh.write("5")
            self._base = _status_mb("VmRSS")
        except OSError:
            self._base = None
        return self

    def __exit__(self, *exc) -> None:
        peak = _status_mb("VmHWM")
        if self._base is not None and peak is not None:
            self.mb = peak - self._base


# -- data ----------------------------------------------------------------------------------------


@dataclass
class Case:
    """One case in working form. ``train`` fits the final model; ``fit_part`` and
    ``validation`` are the selection fit's data and its validation record; ``tests`` the test
    records. ``warmup`` is in samples (every record's first ``warmup`` are not scored)."""

    name: str
    inputs: list[str]
    outputs: list[str]
    train: pd.DataFrame
    fit_part: pd.DataFrame
    validation: pd.DataFrame
    tests: dict[str, pd.DataFrame]
    warmup: int
    unit: str
    scale: float = 1.0
    refit: bool = True  # refit the chosen setting on ``train`` before the test (nlbench)
    warmup_s: float = 0.0  # seamor: nnid's warm-up in seconds (the score's rule)
    notes: dict = field(default_factory=dict)
    seamor: Any = None  # seamor: (config, inputs, split) for nnid_rows


def load_case(name: str) -> Case:
    """The data of case ``name`` (module docstring)."""
    if name == "seamor":
        return _seamor_case()
    cfg = NLBENCH[name]
    bench = load_benchmark(name, ROOT)
    train = bench.splits["train"]
    from bench_nlbench import holdout_parts

    cut = cfg["holdout"]
    cut = cut if isinstance(cut, int) else int(len(train) * cut)
    fit_part, validation = holdout_parts(train, cut, bench.warmup, "tail")
    return Case(
        name=name,
        inputs=list(bench.inputs),
        outputs=list(bench.outputs[:1]),
        train=train,
        fit_part=fit_part,
        validation=validation,
        tests={s: bench.splits[s] for s in cfg["tests"]},
        warmup=bench.warmup,
        unit=cfg["unit"],
        scale=cfg["scale"],
        notes={"official": official_splits(name, bench)},
    )


def _seamor_case() -> Case:
    from nnid.config import TrainConfig, load_config
    from nnid.pipeline import load_inputs, make_split

    cfg = load_config(SEAMOR_CONFIG, TrainConfig)
    inputs = load_inputs(cfg, SEAMOR_CONFIG, [cfg.model])
    split = make_split(inputs.log, cfg.split, str(SEAMOR_CONFIG), inputs.report)
    dt = float(np.median(np.diff(split.train["t"].to_numpy())))
    parts = {p: split[p].reset_index(drop=True) for p in ("train", "validation", "test")}
    net = cfg.model.fitted
    return Case(
        name="seamor",
        inputs=list(net.inputs),
        outputs=list(net.outputs),
        train=parts["train"],
        fit_part=parts["train"],
        validation=parts["validation"],
        tests={"test": parts["test"]},
        warmup=math.ceil(cfg.warmup_s / dt - 1e-9),
        unit="NRMSE",
        refit=False,
        warmup_s=cfg.warmup_s,
        notes={
            "train_runs": list(dict.fromkeys(parts["train"]["experiment"])),
            "validation_runs": list(dict.fromkeys(parts["validation"]["experiment"])),
            "test_runs": list(dict.fromkeys(parts["test"]["experiment"])),
        },
        seamor=(cfg, inputs, split),
    )


def official_splits(name: str, bench) -> dict:
    """Run ``nonlinear-benchmarks``' own loader offline on the shared files and compare its
    splits and warm-ups with nnid's (module docstring). Returns what was compared; raises if
    they differ."""
    import nonlinear_benchmarks as nb
    from scipy.io import savemat

    folder = ROOT / f"nlbench-{name.replace('_', '-')}"
    with tempfile.TemporaryDirectory() as tmp:
        if name == "cascaded_tanks":
            df = pd.read_csv(folder / "dataBenchmark.csv")
            mats = Path(tmp, "Cascaded_Tanks", "CascadedTanksFiles")
            mats.mkdir(parents=True)
            Path(tmp, "Cascaded_Tanks", "CascadedTanksFiles.zip").touch()  # the "cached" zip
            cols = {
                c: df[c].to_numpy(float).reshape(-1, 1) for c in ("uEst", "yEst", "uVal", "yVal")
            }
            savemat(mats / "dataBenchmark.mat", {**cols, "Ts": np.array([[df["Ts"].iloc[0]]])})
            train, test = nb.Cascaded_Tanks(dir_placement=tmp)
            theirs = {"train": train, "test": test}
        elif name == "silverbox":
            df = pd.read_csv(folder / "SNLS80mV.csv")
            mats = Path(tmp, "Silverbox", "SilverboxFiles")
            mats.mkdir(parents=True)
            Path(tmp, "Silverbox", "SilverboxFiles.zip").touch()
            row = {c: df[c].to_numpy(float).reshape(1, -1) for c in ("V1", "V2")}
            savemat(mats / "SNLS80mV.mat", row)
            train, tests = nb.Silverbox(dir_placement=tmp)
            names = ("test_multisine", "test_arrow_full", "test_arrow_no_extrapolation")
            theirs = {"train": train, **dict(zip(names, tests, strict=True))}
        else:
            raise ValueError(name)
    u, y = bench.inputs[0], bench.outputs[0]
    out = {"package": f"nonlinear-benchmarks {_version('nonlinear-benchmarks')}", "splits": {}}
    for split, data in theirs.items():
        ours = bench.splits[split]
        same = (
            len(data) == len(ours)
            and np.array_equal(np.ravel(data.u), ours[u].to_numpy())
            and np.array_equal(np.ravel(data.y), ours[y].to_numpy())
        )
        n_init = data.state_initialization_window_length
        if not same or (split != "train" and n_init != bench.warmup):
            raise RuntimeError(
                f"{name} {split}: nonlinear-benchmarks' split ({len(data)} samples, warm-up "
                f"{n_init}) differs from nnid's ({len(ours)} samples, warm-up {bench.warmup})"
            )
        out["splits"][split] = {"samples": len(data), "warmup": n_init}
    return out


def _version(dist: str) -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(dist)
    except PackageNotFoundError:
        return "not installed"


# -- scores --------------------------------------------------------------------------------------


def score(case: Case, log: pd.DataFrame, pred: np.ndarray, initial: int) -> dict:
    """Free-run error of ``pred`` (n × outputs, in the log's units) on ``log``, by the rules
    behind ``metrics.json`` that nnid's rows are scored by.

    nlbench: ``{"value": RMSE in the case's unit}`` by ``nonlinear_benchmarks.error_metrics.
    RMSE`` over the samples after the warm-up, None where the free run diverged by nnid's rule
    (:func:`common.scored_free_run`, the one nnid's nlbench rows get). Seamor: ``{"value": total
    NRMSE, "per": {column: NRMSE}, "per_run": {run: {column: NRMSE}}}`` by nnid's
    :func:`~nnid.evaluation.evaluate.score_split` (warm-up ``warmup_s`` and ``initial``
    samples; a run that diverged alone makes the pooled column and ``total`` None), and an
    output the data barely moves (left out of the score) that diverged makes ``total`` None
    too (:func:`~nnid.evaluation.evaluate.unscored_divergence`), as :func:`nnid.evaluation.
    evaluate.evaluate` scores nnid's rows."""
    pred = np.asarray(pred, dtype=np.float64).reshape(len(log), -1)
    frame = pd.DataFrame(pred, columns=case.outputs, index=log.index)
    if case.name == "seamor":
        from nnid.datasets.preprocess import excited_dofs
        from nnid.evaluation.evaluate import score_split, scored_rows, unscored_divergence

        columns = excited_dofs(log, case.outputs)
        mask = scored_rows(log, case.warmup_s, initial)
        nrmse, _, diverged, runs, _ = score_split(
            log, frame, columns, mask, lambda run: excited_dofs(run, case.outputs)
        )
        left_out = [c for c in case.outputs if c not in columns]
        gone = unscored_divergence(log, frame, columns, left_out, mask)
        if gone:
            diverged.update(gone)
            nrmse["total"] = None
        per = {c: nrmse[c] for c in columns}
        out = {"value": nrmse["total"], "per": per, "diverged": sorted(diverged)}
        return out | ({"per_run": runs} if runs else {})
    from nonlinear_benchmarks.error_metrics import RMSE

    with np.errstate(all="ignore"):
        ours = scored_free_run(log, frame, case.outputs[0], case.warmup)
    if ours is None:
        return {"value": None, "diverged": case.outputs[:1]}
    y = log[case.outputs[0]].to_numpy(np.float64)
    return {"value": float(RMSE(y, pred[:, 0], n_init=case.warmup)) * case.scale}


# -- SysIdentPy models ---------------------------------------------------------------------------


def _lags(lag: int, n_inputs: int):
    """xlag: an int for one input; for several, one list 1..lag per input (SysIdentPy reads a
    plain int per input as that single lag when it builds the regressors but as 1..lag when it
    names them, so several inputs need the nested lists)."""
    return lag if n_inputs == 1 else [list(range(1, lag + 1)) for _ in range(n_inputs)]


def make_frols(setting: dict, n_inputs: int):
    from sysidentpy.basis_function import Polynomial
    from sysidentpy.model_structure_selection import FROLS
    from sysidentpy.parameter_estimation import LeastSquares

    kw: dict[str, Any] = {}
    if setting.get("order_selection"):
        kw.update(
            order_selection=True,
            info_criteria=setting["info_criteria"],
            n_info_values=setting["n_info_values"],
        )
    else:
        kw.update(order_selection=False, err_tol=setting["err_tol"], n_terms=setting["n_terms"])
    return FROLS(
        ylag=setting["lag"],
        xlag=_lags(setting["lag"], n_inputs),
        basis_function=Polynomial(degree=setting["degree"]),
        estimator=LeastSquares(),
        **kw,
    )


def frols_memory_gb(setting: dict, n_rows: int, n_inputs: int) -> float:
    """Estimated FROLS working memory (GB) on ``n_rows`` samples (:data:`MEMORY_FACTOR`)."""
    n_vars = 1 + setting["lag"] * (1 + n_inputs)  # the constant, y lags, x lags
    candidates = math.comb(n_vars + setting["degree"] - 1, setting["degree"])
    factor = MEMORY_FACTOR["order_selection" if setting.get("order_selection") else "err_tol"]
    return factor * n_rows * candidates * 8 / 1e9


def frols_label(s: dict) -> str:
    how = (
        f"{s['info_criteria']} over {s['n_info_values']} terms"
        if s.get("order_selection")
        else f"err_tol {s['err_tol']}, ≤ {s['n_terms']} terms"
    )
    return f"degree {s['degree']}, lags {s['lag']}, {how}"


class _MLP(torch.nn.Module):
    """One tanh hidden layer (the NARXNN ``net``)."""

    def __init__(self, n_in: int, hidden: int) -> None:
        super().__init__()
        self.lin1 = torch.nn.Linear(n_in, hidden)
        self.lin2 = torch.nn.Linear(hidden, 1)

    def forward(self, x):
        return self.lin2(torch.tanh(self.lin1(x)))


def make_narxnn(setting: dict, n_inputs: int, seed: int, epochs: int | None = None):
    from sysidentpy.basis_function import Polynomial
    from sysidentpy.neural_network import NARXNN

    lag = setting["lag"]
    n_reg = lag * (1 + n_inputs)  # degree 1: the lagged outputs and inputs, no constant
    torch.manual_seed(seed)
    model = NARXNN(
        ylag=lag,
        xlag=lag if n_inputs == 1 else [lag] * n_inputs,
        basis_function=Polynomial(degree=1),
        net=_MLP(n_reg, setting["hidden"]),
        epochs=epochs or setting["epochs"],
        random_state=seed,
    )
    # NARXNN 0.9.0's constructor accepts only ints in xlag, which for several inputs mean one
    # lag each in the regressors (see _lags); its fit and predict take the nested lists
    model.xlag = _lags(lag, n_inputs)
    return model


def narxnn_label(s: dict, epochs: int) -> str:
    return f"lags {s['lag']}, {s['hidden']} tanh units, {epochs} epochs, Adam lr 0.01"


@dataclass
class Scaler:
    """Standardisation by the training mean and std (per column)."""

    mean: np.ndarray
    std: np.ndarray

    @classmethod
    def of(cls, a: np.ndarray) -> Scaler:
        std = a.std(0)
        return cls(a.mean(0), np.where(std > 0, std, 1.0))

    def __call__(self, a: np.ndarray) -> np.ndarray:
        return (a - self.mean) / self.std

    def inverse(self, a: np.ndarray) -> np.ndarray:
        return a * self.std + self.mean


class CoSimulation:
    """Single-output SysIdentPy models, one per output, simulated jointly (Seamor).

    Model ``m`` is fitted with regressors from X_m = [the inputs, the other outputs in output
    order] and its own output. The free run keeps a signal matrix S = [outputs, inputs, 1]; at
    each step k ≥ max_lag every simulated output's model is evaluated from rows < k of S, so
    each model sees the others' simulated outputs. A polynomial model (FROLS) is the sum of
    ``theta`` times its terms, each term the product of the signals its ``final_model`` code
    names (1000·j + lag: j = 1 the model's own output, j = 2 + i its i-th exogenous input); a
    NARXNN model (degree 1) feeds the lagged signals of its ``final_model`` to its ``net``.
    ``check`` compares one output's run with the others fed measured against ``model.predict``.
    """

    def __init__(self, models: list, kind: str, n_inputs: int, scaler: Scaler | None = None):
        self.models, self.kind, self.n_u, self.scaler = models, kind, n_inputs, scaler
        self.n_y = len(models)
        self.one = self.n_y + self.n_u  # the column of ones in S
        self.max_lag = max(int(m.max_lag) for m in models)
        self.terms = [self._terms(k, m) for k, m in enumerate(models)]

    def _terms(self, k: int, model) -> tuple[np.ndarray, np.ndarray]:
        """(columns of S, lags) of each term's factors: arrays n_terms × degree; unused factors
        point at the column of ones with lag 0."""
        others = [j for j in range(self.n_y) if j != k]
        column = {1: k} | {2 + i: self.n_y + i for i in range(self.n_u)}
        column |= {2 + self.n_u + i: o for i, o in enumerate(others)}
        codes = np.atleast_2d(np.asarray(model.final_model, dtype=np.int64))
        cols = np.full(codes.shape, self.one, dtype=np.int64)
        lags = np.zeros(codes.shape, dtype=np.int64)
        for (t, d), code in np.ndenumerate(codes):
            if code:
                cols[t, d], lags[t, d] = column[int(code) // 1000], int(code) % 1000
        return cols, lags

    def exogenous(self, y: np.ndarray, u: np.ndarray, k: int) -> np.ndarray:
        """X_k: the inputs, then the outputs other than k."""
        return np.column_stack([u, np.delete(y, k, axis=1)])

    def run(self, y: np.ndarray, u: np.ndarray, simulate: list[int] | None = None) -> np.ndarray:
        """Free run from the measured ``y[:max_lag]``; outputs not in ``simulate`` (default
        all) stay measured. Returns n × outputs in the units given."""
        simulate = list(range(self.n_y)) if simulate is None else simulate
        dtype = np.float32 if self.kind == "narxnn" else np.float64
        n = len(y)
        s = np.empty((n, self.one + 1), dtype=dtype)
        s[:, : self.n_y], s[:, self.n_y : self.one], s[:, self.one] = y, u, 1.0
        theta = [np.asarray(getattr(m, "theta", [0.0]), dtype=dtype).ravel() for m in self.models]
        with np.errstate(all="ignore"), torch.no_grad():
            for k in range(self.max_lag, n):
                for j in simulate:
                    cols, lags = self.terms[j]
                    values = s[k - lags, cols]
                    if self.kind == "frols":
                        s[k, j] = values.prod(axis=1) @ theta[j]
                    else:
                        x = torch.from_numpy(np.ascontiguousarray(values[:, 0])[None, :])
                        s[k, j] = float(self.models[j].net(x)[0, 0])
        return s[:, : self.n_y].astype(np.float64)

    def check(self, y: np.ndarray, u: np.ndarray) -> float:
        """Largest |difference| / (std(y) + |predict|) between ``run(simulate=[k])`` and
        SysIdentPy's ``predict`` of output k with the other outputs measured, over the outputs
        and the samples where both are finite; inf where only one of them is finite somewhere."""
        worst = 0.0
        for k, model in enumerate(self.models):
            ours = self.run(y, u, simulate=[k])[:, k]
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore")
                theirs = model.predict(X=self.exogenous(y, u, k), y=y[:, k : k + 1]).ravel()
            finite = np.isfinite(ours)
            if not np.array_equal(finite, np.isfinite(theirs)):
                return math.inf
            scale = max(float(np.std(y[:, k])), 1e-12) + np.abs(theirs[finite])
            diff = np.abs(ours[finite] - theirs[finite]) / scale
            worst = max(worst, float(diff.max()) if finite.any() else 0.0)
        return worst


#: the largest co-simulation check (:meth:`CoSimulation.check`) a run accepts: FROLS's checks
#: read 1e-14 (float64); NARXNN's run in float32 (rounding 6e-8 a step), so a check above this
#: is no rounding but a co-simulation that is not SysIdentPy's model, and its scores would be
#: of another model
COSIM_TOLERANCE = 1e-3


def cosim_checked(sim: CoSimulation, y: np.ndarray, u: np.ndarray, what: str) -> float:
    """``sim.check(y, u)``; RuntimeError where it exceeds :data:`COSIM_TOLERANCE`."""
    check = sim.check(y, u)
    if not check <= COSIM_TOLERANCE:
        raise RuntimeError(
            f"{what}: the joint free run (CoSimulation) differs from SysIdentPy's own predict "
            f"by {check:.3g} (largest |difference| / (std + |prediction|), the other outputs "
            f"measured), more than the {COSIM_TOLERANCE:g} it may: its scores would not be "
            "SysIdentPy's model's"
        )
    return check


# -- SysIdentPy rows ----------------------------------------------------------------------------


def _arrays(case: Case, log: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    return log[case.inputs].to_numpy(np.float64), log[case.outputs].to_numpy(np.float64)


def _fit_predictor(
    case: Case,
    kind: str,
    setting: dict,
    log: pd.DataFrame,
    seed: int = 0,
    epochs: int | None = None,
):
    """Fit on ``log``; return (predict(log) -> n × outputs, fit seconds, peak MB, detail).
    FROLS on the raw signals; NARXNN on standardised ones. One model per output for Seamor."""
    u, y = _arrays(case, log)
    scaler = None
    if kind == "narxnn":
        scaler = Scaler.of(np.column_stack([y, u]))
        yu = scaler(np.column_stack([y, u]))
        y, u = yu[:, : y.shape[1]], yu[:, y.shape[1] :]
    n_ex = u.shape[1] + y.shape[1] - 1
    models = [  # built before the clock starts (imports, network initialisation)
        make_frols(setting, n_ex) if kind == "frols" else make_narxnn(setting, n_ex, seed, epochs)
        for _ in range(y.shape[1])
    ]
    with PeakMemory() as mem, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        for k, model in enumerate(models):
            model.fit(X=np.column_stack([u, np.delete(y, k, axis=1)]), y=y[:, k : k + 1])
        fit_s = time.perf_counter() - t0
    sim = CoSimulation(models, kind, u.shape[1], scaler)
    terms = [len(m.final_model) for m in models] if kind == "frols" else None

    def predict(test: pd.DataFrame) -> np.ndarray:
        # each run its own free run from its own measured start, as nnid scores a split
        if "experiment" in test and test["experiment"].nunique() > 1:
            out = np.empty((len(test), len(case.outputs)))
            for rows in test.groupby("experiment", sort=False).indices.values():
                out[rows] = predict(test.iloc[rows])
            return out
        tu, ty = _arrays(case, test)
        if scaler is not None:
            tyu = scaler(np.column_stack([ty, tu]))
            ty, tu = tyu[:, : ty.shape[1]], tyu[:, ty.shape[1] :]
        if len(models) == 1:  # single output: SysIdentPy's own free run
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore")
                out = models[0].predict(X=tu, y=ty[:, :1]).reshape(-1, 1).astype(np.float64)
        else:
            out = sim.run(ty, tu)
        if scaler is not None:
            out = (scaler.inverse(np.column_stack([out, tu])))[:, : out.shape[1]]
        return out

    return predict, fit_s, mem.mb, {"terms": terms, "sim": sim, "max_lag": sim.max_lag}


def _row(case: Case, toolkit: str, model: str, setting: str, **kw) -> dict:
    row = {
        "case": case.name,
        "toolkit": toolkit,
        "model": model,
        "setting": setting,
        "unit": case.unit,
        "test": {},
        "validation": None,
        "fit_s": None,  # the model's: an ensemble's is all its members' fits
        "member_fit_s": None,  # an ensemble's members: their median fit
        "peak_mb": None,
        "note": "",
    }
    row.update(kw)
    return row


def frols_rows(case: Case, quick: bool, max_gb: float) -> list[dict]:
    """FROLS: every grid setting on the validation part; the chosen one (and the book's
    settings) refitted on the whole training split (nlbench) and scored on the test splits."""
    grid = FROLS_GRID[case.name]
    picks = [grid[i] for i in FROLS_QUICK[case.name]] if quick else grid
    rows, val, fits = [], {}, {}
    n_in = len(case.inputs) + len(case.outputs) - 1
    for i, s in enumerate(picks):
        label = frols_label(s)
        book = f" (book, {s['book']})" if "book" in s else ""
        gb = frols_memory_gb(s, len(case.train), n_in)
        if gb > max_gb:
            note = f"skipped: needs ≈{gb:.1f} GB > --max-gb {max_gb:g}{book}"
            rows.append(_row(case, "SysIdentPy", "FROLS", label, note=note))
            print(f"  FROLS {label}: {note}", flush=True)
            continue
        predict, fit_s, mb, det = _fit_predictor(case, "frols", s, case.fit_part)
        fits[i] = (predict, det)
        v = score(case, case.validation, predict(case.validation), det["max_lag"])
        val[i] = v["value"]
        row = _row(case, "SysIdentPy", "FROLS", label, validation=v, fit_s=fit_s, peak_mb=mb)
        row.update(terms=det["terms"], memory_estimate_gb=gb, _i=i)
        if case.name == "seamor":
            row["cosim_check"] = cosim_checked(
                det["sim"], *_arrays(case, case.validation)[::-1], f"FROLS {label}"
            )
        rows.append(row)
        print(
            f"  FROLS {label}: validation {_fmt(v)}, fit {fit_s:.1f} s, peak {_r(mb)} MB, "
            f"terms {det['terms']}"
            + (f", co-sim check {row['cosim_check']:.1e}" if "cosim_check" in row else ""),
            flush=True,
        )
    ok = {i: v for i, v in val.items() if v is not None}
    chosen = min(ok, key=ok.get) if ok else None
    for row in rows:
        i = row.pop("_i", None)
        if i is None:
            continue
        book = picks[i].get("book")
        row["chosen"] = i == chosen
        if i != chosen and not book:
            continue
        row["note"] = "; ".join(
            x
            for x in (
                "chosen on validation" if i == chosen else "",
                f"book setting ({book})" if book else "",
            )
            if x
        )
        if case.refit:
            row.update(selection_fit_s=row["fit_s"], selection_terms=row["terms"])
            predict, fit_s, mb, det = _fit_predictor(case, "frols", picks[i], case.train)
            row.update(fit_s=fit_s, peak_mb=mb, terms=det["terms"])
        else:  # seamor: the validation fit is the model
            predict, det = fits[i]
        for split, log in case.tests.items():
            row["test"][split] = score(case, log, predict(log), det["max_lag"])
        print(f"  FROLS {row['setting']} ({row['note']}): test {_fmt_tests(row)}", flush=True)
    return rows


def narxnn_rows(case: Case, quick: bool, seeds: tuple[int, ...]) -> list[dict]:
    """NARXNN: each setting on the validation part over ``seeds``; the chosen one (lowest
    median validation error) refitted per seed and scored on the test splits (median over the
    seeds; every seed in ``per_seed``)."""
    grid = NARXNN_GRID[case.name]
    picks = grid[:1] if quick else grid
    rows, med = [], {}
    for i, s in enumerate(picks):
        epochs = NARXNN_QUICK_EPOCHS[case.name] if quick else s["epochs"]
        vals, times, mems, fits = [], [], [], {}
        for seed in seeds:
            predict, fit_s, mb, det = _fit_predictor(case, "narxnn", s, case.fit_part, seed, epochs)
            vals.append(score(case, case.validation, predict(case.validation), det["max_lag"]))
            times.append(fit_s)
            mems.append(mb)
            fits[seed] = (predict, det)
        med[i] = _median([v["value"] for v in vals])
        row = _row(
            case,
            "SysIdentPy",
            "NARXNN",
            narxnn_label(s, epochs),
            validation={
                "value": med[i],
                "per_seed": [v["value"] for v in vals],
                **(
                    {"per": {c: _median([v["per"].get(c) for v in vals]) for c in vals[0]["per"]}}
                    if "per" in vals[0]
                    else {}
                ),
            },
            fit_s=float(np.median(times)),
            peak_mb=_max(mems),
            seeds=list(seeds),
        )
        if case.name == "seamor":
            sim = fits[seeds[0]][1]["sim"]
            y, u = (a.astype(np.float64) for a in _scaled(case, sim.scaler))
            row["cosim_check"] = cosim_checked(sim, y, u, f"NARXNN {row['setting']}")
        row["_fits"], row["_epochs"], row["_s"] = fits, epochs, s
        rows.append(row)
        print(
            f"  NARXNN {row['setting']}: validation per seed "
            f"{[_r(v['value']) for v in vals]}, fit {np.median(times):.1f} s"
            + (f", co-sim check {row['cosim_check']:.1e}" if "cosim_check" in row else ""),
            flush=True,
        )
    ok = {i: v for i, v in med.items() if v is not None}
    chosen = min(ok, key=ok.get) if ok else None
    out = []
    for i, row in enumerate(rows):
        fits, epochs, s = row.pop("_fits"), row.pop("_epochs"), row.pop("_s")
        row["chosen"] = i == chosen
        if i != chosen:
            out.append(row)
            continue
        row["chosen"], row["note"] = True, "chosen on validation (median over seeds)"
        times, mems = [], []
        per: dict[str, list] = {split: [] for split in case.tests}
        for seed in seeds:
            if case.refit:
                predict, fit_s, mb, det = _fit_predictor(
                    case, "narxnn", s, case.train, seed, epochs
                )
                times.append(fit_s)
                mems.append(mb)
            else:
                predict, det = fits[seed]
            for split, log in case.tests.items():
                per[split].append(score(case, log, predict(log), det["max_lag"]))
        if times:
            row.update(selection_fit_s=row["fit_s"])
            row.update(fit_s=float(np.median(times)), peak_mb=_max(mems))
        for split, scores in per.items():
            row["test"][split] = {
                "value": _median([x["value"] for x in scores]),
                "per_seed": [x["value"] for x in scores],
            }
            if case.name == "seamor":
                cols = scores[0]["per"]
                row["test"][split]["per"] = {
                    c: _median([x["per"].get(c) for x in scores]) for c in cols
                }
        print(
            f"  NARXNN {row['setting']} (chosen): test {_fmt_tests(row)} "
            f"per seed {[[_r(x) for x in v['per_seed']] for v in row['test'].values()]}",
            flush=True,
        )
        out.append(row)
    return out


def _scaled(case: Case, scaler: Scaler) -> tuple[np.ndarray, np.ndarray]:
    """The validation record standardised as the NARXNN models see it: (y, u)."""
    u, y = _arrays(case, case.validation)
    yu = scaler(np.column_stack([y, u]))
    return yu[:, : y.shape[1]], yu[:, y.shape[1] :]


def sysidentpy_rows(case: Case, quick: bool, seeds: tuple[int, ...], max_gb: float) -> list[dict]:
    import sysidentpy

    print(f"{case.name}: SysIdentPy {sysidentpy.__version__}", flush=True)
    return frols_rows(case, quick, max_gb) + narxnn_rows(case, quick, seeds)


# -- nnid rows ----------------------------------------------------------------------------------
# Clearly the place to change nnid's side: the NARX and the neural state-space model. The nlbench
# cases reuse benchmarks/bench_nlbench.py (its SETTINGS, run(), ensembles): a setting
# "<case>_nss" there adds the state-space row of that case. Seamor: the configs below, fitted
# through the library as `nnid train` does (nnid.pipeline), scored with nnid's evaluate().

SEAMOR_NNID_CONFIGS = {
    "NARX (LM)": SEAMOR_CONFIG,
    "NARX (Adam)": REPO / "configs" / "seamor_narx_adam.toml",
}
SEAMOR_NNID_SEEDS = (0, 1, 2)


def nnid_rows(case: Case, seeds: tuple[int, ...] | None = None, quick: bool = False) -> list[dict]:
    """Rows for nnid's models on ``case`` (``seeds``: None = each setting's own)."""
    if case.name == "seamor":
        return _nnid_seamor(case, seeds or SEAMOR_NNID_SEEDS[: 1 if quick else None])
    import bench_nlbench as nl

    rows = []
    for name, model in ((case.name, "NARX"), (f"{case.name}_nss", "neural state space")):
        if name not in nl.SETTINGS:
            rows.append(
                _row(
                    case, "nnid", model, "–", note=f"no setting '{name}' in bench_nlbench.SETTINGS"
                )
            )
            continue
        cfg = nl.SETTINGS[name]
        use = tuple(seeds) if seeds is not None else tuple(cfg["seeds"])
        if quick:
            use = use[:1]
        pairs = nl.members(name, use)  # every seed once per variant of the setting
        per: dict[str, list] = {s: [] for s in case.tests}
        preds: dict[str, list] = {s: [] for s in case.tests}
        times, mems, labels = [], [], []
        for seed, variant in pairs:
            with PeakMemory() as mem:
                res = nl.run(name, seed, variant=variant)
            times.append(res["fit_s"])
            mems.append(mem.mb)
            var = f" variant {variant}" if "variants" in cfg else ""
            labels.append(f"seed {seed}{var}")
            for split in case.tests:
                per[split].append(res[split])
                preds[split].append(res["pred"][split])
            print(
                f"  nnid {model} {labels[-1]}: test "
                f"{ {s: _r(per[s][-1]) for s in per} }, fit {res['fit_s']:.1f} s",
                flush=True,
            )
        ens = cfg.get("ensemble") if len(pairs) > 1 else None
        row = _row(
            case,
            "nnid",
            model,
            _nnid_label(cfg),
            # an ensemble's cost is all its members' fits; a median member is one fit
            fit_s=float(np.sum(times)) if ens else float(np.median(times)),
            member_fit_s=float(np.median(times)),
            peak_mb=_max(mems),
            seeds=list(use),
            note=f"settings of bench_nlbench.SETTINGS['{name}']",
        )
        for split in case.tests:
            entry = {"value": _median(per[split]), "per_seed": per[split]}
            if ens:
                runs = preds[split]
                got = ensemble_free_run(
                    runs[0][1], [p for p, _ in runs], labels, res["output"], res["warmup"]
                )
                value = got[ens]
                entry["value"] = None if value is None else value * cfg["scale"]
                entry["ensemble"] = ens
                if got["wild"]:  # the ensemble diverged with them: named, not averaged away
                    entry["wild_members"] = got["wild"]
                    print(f"  nnid {model} {split}: wild member(s) {got['wild']}", flush=True)
            row["test"][split] = entry
        row["note"] += (
            f"; test = {ens} of the {len(pairs)} members' free runs; fit = all members'"
            if ens
            else f"; test = median over {len(pairs)} member(s)"
        )
        rows.append(row)
    return rows


def _nnid_label(cfg: dict) -> str:
    if "nss" in cfg:
        s = cfg["nss"]
        return (
            f"{1 + s['hidden_states']} states, {s['hidden']} tanh units per derivative, "
            f"LM {cfg['lm_epochs']} epochs per stage"
        )
    s = cfg["narx"]
    text = (
        f"delays {s['input_delays']}/{s['output_delays']}, hidden {tuple(s['hidden'])}, "
        f"LM {cfg['lm_epochs']} epochs one-step"
    )
    if s.get("simulation_epochs"):
        text += (
            f", then {s.get('simulation_trainer', 'adam')} on the free-run error of windows "
            f"{s.get('simulation_window')}, {s['simulation_epochs']} epochs each"
        )
        if s.get("simulation_l2"):
            text += f", penalty {s['simulation_l2']:g} ‖θ‖²"
    for v in cfg.get("variants", ())[1:]:
        text += f"; each seed again with {', '.join(f'{k} {x}' for k, x in v.items())}"
    return text


def _nnid_seamor(case: Case, seeds: tuple[int, ...]) -> list[dict]:
    from nnid.config import TrainConfig, load_config
    from nnid.evaluation.evaluate import evaluate
    from nnid.pipeline import fit_model
    from nnid.trainers.history import silent

    _, inputs, split = case.seamor
    rows = []
    for model_name, path in SEAMOR_NNID_CONFIGS.items():
        per: dict[str, list] = {"validation": [], "test": []}
        times, mems = [], []
        # an ensemble config is one model (its own seeds); a single net is fitted per seed
        ensemble = load_config(path, TrainConfig).model.kind == "ensemble"
        for seed in [None] if ensemble else seeds:
            overrides = {} if seed is None else {"model.seed": seed}
            cfg = load_config(path, TrainConfig, overrides=overrides)
            model = cfg.model.build(inputs.vehicle)
            with PeakMemory() as mem:
                t0 = time.perf_counter()
                fit_model(model, split, silent, "model", cfg.model)
                times.append(time.perf_counter() - t0)
            mems.append(mem.mb)
            for part in per:
                with np.errstate(all="ignore"):
                    res = evaluate(model, split[part], ("free_run",), None, cfg.warmup_s)
                nr = res["free_run_nrmse"]
                per[part].append(
                    {
                        "value": nr["total"],
                        "per": {c: nr[c] for c in res["columns"]},
                        "diverged": sorted(res["diverged"]),
                        # pooled scores can hide one run's miss: each run scored alone too
                        "per_run": res.get("free_run_nrmse_per_experiment", {}),
                    }
                )
            print(
                f"  nnid {model_name} {'ensemble' if seed is None else f'seed {seed}'}: "
                f"validation {_fmt(per['validation'][-1])}, "
                f"test {_fmt(per['test'][-1])}, fit {times[-1]:.1f} s",
                flush=True,
            )
        net = cfg.model.fitted
        setting = (
            f"{Path(path).name}: {cfg.model.kind}, delays {net.input_delays}/"
            f"{net.output_delays}, hidden {tuple(net.hidden)}"
        )
        workers = ensemble and cfg.model.n_jobs > 1
        if ensemble:
            note = f"{cfg.model.combine} of seeds {cfg.model.seeds}; validation = early stopping"
            if workers:  # PeakMemory reads this process only
                note += "; members fitted in worker processes: peak memory not measured"
        else:
            note = f"median over {len(seeds)} seed(s); validation = early stopping"
        row = _row(
            case,
            "nnid",
            model_name,
            setting,
            fit_s=float(np.median(times)),
            peak_mb=None if workers else _max(mems),
            seeds=list(cfg.model.seeds if ensemble else seeds),
            note=note,
        )
        for part, scores in per.items():
            entry = {
                "value": _median([x["value"] for x in scores]),
                "per_seed": [x["value"] for x in scores],
                "per": {c: _median([x["per"][c] for x in scores]) for c in scores[0]["per"]},
            }
            entry["per_run"] = {
                run: {c: _median([x["per_run"][run][c] for x in scores]) for c in cols}
                for run, cols in scores[0]["per_run"].items()
            }
            if part == "validation":
                row["validation"] = entry
            else:
                row["test"]["test"] = entry
        rows.append(row)
    rows.append(
        _row(
            case,
            "nnid",
            "neural state space",
            "–",
            note="no Seamor state-space config yet (SEAMOR_NNID_CONFIGS)",
        )
    )
    return rows


# -- table ---------------------------------------------------------------------------------------


def _median(values) -> float | None:
    """Median of the values; None if any is None (a diverged seed is not hidden)."""
    values = list(values)
    if not values or any(v is None for v in values):
        return None
    return float(np.median(values))


def _max(values) -> float | None:
    values = [v for v in values if v is not None]
    return max(values) if values else None


def _r(x) -> str:
    return "diverged" if x is None else f"{x:.4g}"


def _fmt(entry: dict | None) -> str:
    if not entry:
        return ""
    text = _r(entry.get("value"))
    if entry.get("per"):
        text += " (" + ", ".join(f"{c} {_r(v)}" for c, v in entry["per"].items()) + ")"
    if len(entry.get("per_run", {})) > 1:  # one run alone is the pooled score
        for run, scores in entry["per_run"].items():
            text += f"; {run} alone: " + ", ".join(f"{c} {_r(v)}" for c, v in scores.items())
    return text


def _fmt_tests(row: dict) -> str:
    return "; ".join(f"{s}: {_fmt(e)}" for s, e in row["test"].items())


def table(rows: list[dict]) -> str:
    lines = [
        "| case | toolkit | model | setting | free-run test error | validation | fit (s) | "
        "member fit, median (s) | peak memory (MB) | note |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        unit = r["unit"]
        test = "; ".join(f"{s} **{_fmt(e)}**" for s, e in r["test"].items())
        if test:
            test += f" {unit}" if unit != "NRMSE" else " (NRMSE)"
        fit = f"{r['fit_s']:.3g}" if r["fit_s"] is not None else ""
        member = f"{r['member_fit_s']:.3g}" if r["member_fit_s"] is not None else ""
        val = r["validation"]
        val_unit = f" {unit}" if val and val.get("value") is not None and unit != "NRMSE" else ""
        mem = f"{r['peak_mb']:.0f}" if r["peak_mb"] is not None else ""
        lines.append(
            f"| {r['case']} | {r['toolkit']} | {r['model']} | {r['setting']} | {test} | "
            f"{_fmt(r['validation'])}{val_unit} | {fit} | {member} | {mem} | {r['note']} |"
        )
    return "\n".join(lines)


def _jsonable(x):
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items() if not k.startswith("_")}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, Path):
        return str(x)
    return x


def main(argv: list[str] | None = None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="*", help=f"among {', '.join(CASES)} (default: all)")
    ap.add_argument(
        "--seeds",
        help="comma-separated seeds for NARXNN and nnid (default: "
        "NARXNN 0,1,2; nnid the seeds of its settings)",
    )
    ap.add_argument("--quick", action="store_true", help="fewer settings and epochs: a smoke run")
    ap.add_argument("--only", choices=["sysidentpy", "nnid"], help="one toolkit only")
    ap.add_argument(
        "--max-gb",
        type=float,
        default=10.0,
        help="skip FROLS settings estimated to need more memory (GB)",
    )
    ap.add_argument("--json", type=Path, help="write the rows to this file")
    args = ap.parse_args(argv)
    seeds = tuple(int(s) for s in args.seeds.split(",")) if args.seeds else None
    unknown = [c for c in args.cases if c not in CASES]
    if unknown:
        ap.error(f"unknown case(s) {', '.join(unknown)}; expected among {', '.join(CASES)}")

    import sysidentpy

    versions = machine(
        torch=torch.__version__,
        numpy=np.__version__,
        sysidentpy=sysidentpy.__version__,
        **{"nonlinear-benchmarks": _version("nonlinear-benchmarks")},
    )
    print(f"Machine: {versions}. Date: {date.today()}. torch threads: {torch.get_num_threads()}.")
    rows: list[dict] = []

    def save() -> None:  # after every toolkit's rows, so a late failure keeps what was measured
        if args.json:
            header = {"machine": versions, "date": str(date.today()), "argv": argv or sys.argv[1:]}
            args.json.write_text(json.dumps(_jsonable({**header, "rows": rows}), indent=1))

    for name in args.cases or CASES:
        case = load_case(name)
        if "official" in case.notes:
            print(
                f"{name}: nonlinear-benchmarks splits and warm-ups equal nnid's: "
                f"{case.notes['official']}",
                flush=True,
            )
        else:
            print(f"{name}: {case.notes}", flush=True)
        if args.only != "nnid":
            rows += sysidentpy_rows(case, args.quick, seeds or NARXNN_SEEDS, args.max_gb)
            save()
        if args.only != "sysidentpy":
            rows += nnid_rows(case, seeds, args.quick)
            save()
    print()
    print(table(rows))
    if args.json:
        print(f"\nwrote {args.json}")
    return rows


if __name__ == "__main__":
    main()
