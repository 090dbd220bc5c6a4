"""Generic input-output benchmarks of nonlinearbenchmark.org, in their standard splits.

``load_benchmark(name, root)`` reads one of the ``nlbench-*`` folders under ``../shared/data`` (see
each folder's ``SOURCE.md``) and returns a :class:`Benchmark`: the input and output column names,
the sampling interval, the standard splits as tables (``t``, ``experiment``, inputs, outputs;
the columns keep the names they have in the files), the warm-up window that the benchmark leaves
out of the score (its state-initialisation window) and the published test RMSEs quoted in the
``SOURCE.md`` (none of the current ones quotes any, so ``published`` is empty).

These are not vehicle logs: there are no pose or velocity columns, so they do not go through the
vehicle-log validator; they feed NARX and neural-ODE quality checks.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from nnid.errors import NnidInputError

BENCHMARKS = ("silverbox", "cascaded_tanks", "emps", "boucwen", "f16")


@dataclass
class Benchmark:
    """One benchmark in its standard splits.

    ``splits`` maps a split name (``train``, ``test`` or ``test_<variant>``) to a table with
    columns ``t`` (s, from 0 in each experiment), ``experiment``, the ``inputs`` and the
    ``outputs``. ``warmup`` is the number of samples at the start of each test experiment that
    may be used to initialise a model's state and are left out of the score.
    """

    name: str
    inputs: list[str]
    outputs: list[str]
    dt: float
    splits: dict[str, pd.DataFrame]
    warmup: int
    published: dict = field(default_factory=dict)
    source: str = ""
    notes: str = ""


def _folder(root: str | Path, name: str) -> Path:
    """The benchmark folder: ``root/nlbench-<name>`` or ``root`` itself."""
    root = Path(root)
    sub = root / f"nlbench-{name.replace('_', '-')}"
    if sub.is_dir():
        return sub
    if root.is_dir() and not any(root.glob("nlbench-*")):
        return root
    raise NnidInputError(
        f"no folder nlbench-{name.replace('_', '-')} for benchmark '{name}'", source=str(root)
    )


def _csv(path: Path) -> pd.DataFrame:
    if not path.exists():
        raise NnidInputError("file not found", source=str(path))
    try:
        df = pd.read_csv(path)
    except Exception as err:  # pandas raises many types for a corrupt file
        raise NnidInputError(f"cannot be read as CSV ({err})", source=str(path)) from None
    return df.loc[:, ~df.columns.str.startswith("Unnamed")]  # trailing comma -> empty column


def _mat(path: Path, keys: list[str]) -> dict[str, np.ndarray]:
    from scipy.io import loadmat

    if not path.exists():
        raise NnidInputError("file not found", source=str(path))
    try:
        data = loadmat(path)
    except Exception as err:  # scipy raises several types for a corrupt file
        raise NnidInputError(f"cannot be read as a MATLAB file ({err})", source=str(path)) from None
    missing = [k for k in keys if k not in data]
    if missing:
        raise NnidInputError(
            f"variable(s) {', '.join(missing)} missing; the file has "
            f"{', '.join(k for k in data if not k.startswith('__'))}",
            source=str(path),
        )
    return {k: np.asarray(data[k]) for k in keys}


def _h5(path: Path, keys: list[str]) -> dict[str, np.ndarray]:
    if not path.exists():
        raise NnidInputError("file not found", source=str(path))
    try:
        import h5py
    except ImportError:
        raise NnidInputError(
            "reading this HDF5 file needs h5py: pip install h5py (or the dev extra, "
            "pip install -e '.[dev]')",
            source=str(path),
        ) from None
    try:
        with h5py.File(path, "r") as fh:
            missing = [k for k in keys if k not in fh]
            if missing:
                raise NnidInputError(f"dataset(s) {', '.join(missing)} missing", source=str(path))
            return {k: np.asarray(fh[k][()]) for k in keys}
    except NnidInputError:
        raise
    except Exception as err:  # h5py raises OSError and others for a corrupt file
        raise NnidInputError(f"cannot be read as HDF5 ({err})", source=str(path)) from None


def _table(
    experiment: str, dt: float, columns: dict[str, np.ndarray], t=None, source: str = ""
) -> pd.DataFrame:
    """One experiment as a table; ``t`` from 0 at ``dt`` unless given."""
    flat = {k: np.asarray(v, np.float64).ravel() for k, v in columns.items()}
    lengths = {len(v) for v in flat.values()}
    if len(lengths) != 1:
        raise NnidInputError(
            f"signals of different lengths for '{experiment}': "
            + ", ".join(f"{k} {len(v)}" for k, v in flat.items()),
            source=source or None,
        )
    n = lengths.pop()
    time = np.arange(n) * dt if t is None else np.asarray(t, np.float64).ravel() - float(t[0])
    return pd.DataFrame({"t": time, "experiment": experiment} | flat)


def _silverbox(folder: Path) -> Benchmark:
    # nonlinear-benchmarks 1.0.1 Silverbox(), as in SOURCE.md: arrow [100:40575] (no-extrapolation
    # part = its first 32,000), multisine [40650:127400] split 75 % train / 25 % test, n_init 50
    path = folder / "SNLS80mV.csv"
    df = _csv(path)
    for col in ("V1", "V2"):
        if col not in df:
            raise NnidInputError(f"column '{col}' missing", source=str(path), field=col)
    dt = 1.0 / 610.35  # SOURCE.md: fs = 610.35 Hz (exactly 1e7 / 2**14)
    u, y = df["V1"].to_numpy(), df["V2"].to_numpy()
    arrow = slice(100, 40575)
    multisine = np.arange(40650, 127400)
    cut = int(len(multisine) * 0.75)

    def part(name: str, idx) -> pd.DataFrame:
        return _table(name, dt, {"V1": u[idx], "V2": y[idx]})

    return Benchmark(
        name="silverbox",
        inputs=["V1"],
        outputs=["V2"],
        dt=dt,
        splits={
            "train": part("multisine_train", multisine[:cut]),
            "test_multisine": part("multisine_test", multisine[cut:]),
            "test_arrow_full": part("arrow_full", arrow),
            "test_arrow_no_extrapolation": part("arrow_no_extrapolation", slice(100, 32100)),
        },
        warmup=50,
        source=str(folder),
        notes="u = V1 (V), y = V2 (V); report RMSE in mV (SOURCE.md).",
    )


def _cascaded_tanks(folder: Path) -> Benchmark:
    path = folder / "dataBenchmark.csv"
    df = _csv(path)
    for col in ("uEst", "yEst", "uVal", "yVal", "Ts"):
        if col not in df:
            raise NnidInputError(f"column '{col}' missing", source=str(path), field=col)
    dt = float(df["Ts"].iloc[0])  # 4 s, first row only
    return Benchmark(
        name="cascaded_tanks",
        inputs=["u"],
        outputs=["y"],
        dt=dt,
        splits={
            "train": _table("Est", dt, {"u": df["uEst"], "y": df["yEst"]}),
            "test": _table("Val", dt, {"u": df["uVal"], "y": df["yVal"]}),
        },
        warmup=50,
        source=str(folder),
        notes="u = pump voltage (V), y = lower-tank level sensor (V, overflow saturates at 10 V); "
        "RMSE in V. n_init = 50 per SOURCE.md (nonlinear-benchmarks 1.0.1 too; 1.0.0 had 5).",
    )


def _emps(folder: Path) -> Benchmark:
    splits = {}
    for split, stem in (("train", "DATA_EMPS"), ("test", "DATA_EMPS_PULSES")):
        data = _mat(folder / f"{stem}.mat", ["t", "vir", "qm"])
        splits[split] = _table(
            stem, 1e-3, {"vir": data["vir"], "qm": data["qm"]}, t=data["t"].ravel()
        )
    return Benchmark(
        name="emps",
        inputs=["vir"],
        outputs=["qm"],
        dt=1e-3,
        splits=splits,
        warmup=20,
        source=str(folder),
        notes="u = vir (V; force = 35.15 N/V * vir), y = qm (motor position, m); closed-loop data.",
    )


def _boucwen(folder: Path) -> Benchmark:
    train = _h5(folder / "train_forgione_generated.h5", ["multisine/u", "multisine/y"])
    dt = 1.0 / 750.0  # SOURCE.md: fs = 750 Hz
    splits = {
        "train": _table(
            "multisine_train", dt, {"u": train["multisine/u"], "y": train["multisine/y"]}
        )
    }
    for kind in ("multisine", "sinesweep"):
        u = _mat(folder / f"uval_{kind}.mat", [f"uval_{kind}"])[f"uval_{kind}"]
        y = _mat(folder / f"yval_{kind}.mat", [f"yval_{kind}"])[f"yval_{kind}"]
        splits[f"test_{kind}"] = _table(kind, dt, {"u": u, "y": y}, source=str(folder))
    return Benchmark(
        name="boucwen",
        inputs=["u"],
        outputs=["y"],
        dt=dt,
        splits=splits,
        warmup=0,
        source=str(folder),
        notes="Simulated benchmark: u = force (N), y = displacement (m). Training set generated by "
        "Forgione with the benchmark's script (not the official one). SOURCE.md gives no n_init.",
    )


def _f16(folder: Path) -> Benchmark:
    splits: dict[str, list[pd.DataFrame]] = {"train": [], "test": []}
    dt = None
    for stem in (
        "F16Data_FullMSine_Level1",
        "F16Data_FullMSine_Level3",
        "F16Data_FullMSine_Level2_Validation",
        "F16Data_FullMSine_Level4_Validation",
    ):
        data = _mat(folder / f"{stem}.mat", ["Force", "Acceleration", "Fs"])
        dt = 1.0 / float(data["Fs"].ravel()[0])
        acc = data["Acceleration"]
        columns = {"Force": data["Force"]} | {
            f"Acceleration{k + 1}": acc[k] for k in range(acc.shape[0])
        }
        splits["test" if "Validation" in stem else "train"].append(_table(stem, dt, columns))
    return Benchmark(
        name="f16",
        inputs=["Force"],
        outputs=["Acceleration1", "Acceleration2", "Acceleration3"],
        dt=float(dt),
        splits={k: pd.concat(v, ignore_index=True) for k, v in splits.items()},
        warmup=50,
        source=str(folder),
        notes="u = shaker force (N), y = accelerations at three locations (m/s^2); the standard "
        "loader scores one output channel (output_index). FullMSine subset only (SOURCE.md).",
    )


_LOADERS: dict[str, Callable[[Path], Benchmark]] = {
    "silverbox": _silverbox,
    "cascaded_tanks": _cascaded_tanks,
    "emps": _emps,
    "boucwen": _boucwen,
    "f16": _f16,
}


def load_benchmark(name: str, root: str | Path) -> Benchmark:
    """Benchmark ``name`` (silverbox, cascaded_tanks, emps, boucwen, f16) from ``root``.

    ``root`` is the folder holding the ``nlbench-*`` folders (``../shared/data``) or the
    benchmark's own folder. Missing or unreadable files are an :class:`NnidInputError` naming
    the file; the Bouc-Wen training file needs h5py.
    """
    key = name.lower().replace("-", "_")
    if key not in _LOADERS:
        raise NnidInputError(
            f"unknown benchmark '{name}'; expected one of {', '.join(BENCHMARKS)}", field="name"
        )
    return _LOADERS[key](_folder(root, key))
