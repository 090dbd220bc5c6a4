"""How much of the Seamor's Munk-driven yaw one coefficient decides (issue 14, round 11).

Simulates the ``surge-sway-c`` run of ``configs/seamor_sequence_narx.toml`` (X and Y stairs, no
N force) noise-free with the ``seamor`` preset (Weiss Table 3 truth) and with the same vehicle
with one coefficient scaled, and prints the yaw rate's NRMSE between the two runs. Without an
N force the yaw comes from the Munk moment (X_u̇ − Y_v̇) u v (Weiss eqs 27-28), whose
coefficient is the difference of two 26-27 kg added masses.

Run: ``python benchmarks/bench_munk_sensitivity.py`` (a few seconds).
"""

from __future__ import annotations

import copy
import tomllib
from importlib import resources

import numpy as np

from nnid.config import Experiment
from nnid.datasets.simulator import experiment_inputs, simulate
from nnid.vehicle import vehicle_from_dict

SIGNALS = [  # surge-sway-c of configs/seamor_sequence_narx.toml
    {"kind": "stairs", "channel": "X", "levels": [-18.0, 21.0, -27.0, 9.0, 27.0, 0.0], "hold": 6.5},
    {"kind": "stairs", "channel": "Y", "levels": [12.0, -24.0, 21.0, -6.0, 0.0], "hold": 9.0},
]
CHANGES = [
    ("X_u̇ + 2 %", ("added_mass", "X_udot"), 1.02),
    ("X_u̇ + 0.5 %", ("added_mass", "X_udot"), 1.005),
    ("X_u̇ + 0.2 %", ("added_mass", "X_udot"), 1.002),
    ("N_r|r| + 5 %", ("damping", "coefficients", "N:r*abs(r)"), 1.05),
    ("N_r|r| + 2 %", ("damping", "coefficients", "N:r*abs(r)"), 1.02),
    ("N_ṙ + 10 %", ("added_mass", "N_rdot"), 1.10),
    ("Y_v|v| + 2 %", ("damping", "coefficients", "Y:v*abs(v)"), 1.02),
]


def yaw(spec: dict) -> np.ndarray:
    """The noise-free yaw rate of surge-sway-c for a vehicle given as its preset dict."""
    inputs = experiment_inputs(
        Experiment(name="surge-sway-c", signals=SIGNALS), tuple("XYZKMN"), 0.01
    )
    log = simulate(vehicle_from_dict(spec, source="seamor (scaled)"), inputs, 0.01, seed=0)
    return log["r"].to_numpy()


def main() -> None:
    base = tomllib.loads(resources.files("nnid.presets").joinpath("seamor.toml").read_text())
    am = base["added_mass"]
    print(f"Munk coefficient X_u̇ − Y_v̇ = {am['X_udot'] - am['Y_vdot']:.3f} kg")
    r0 = yaw(base)
    print("| change | yaw NRMSE on surge-sway-c |\n|---|---|")
    for label, path, factor in CHANGES:
        spec = copy.deepcopy(base)
        node = spec
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] *= factor
        r = yaw(spec)
        print(f"| {label} | {np.sqrt(np.mean((r - r0) ** 2)) / r0.std():.3f} |")


if __name__ == "__main__":
    main()
