"""Make nnid/demo_data/demo_minirov_heave.parquet, the log ``nnid demo`` runs on.

A SIMULATED log, not a measurement: the 'minirov' vehicle (nnid/demo_data/minirov.toml) driven
in all six DOFs by random multisine forces, with one effect its vehicle file does not declare:
upward heave thrust at 57 % of nominal (Caccia's installation coefficient, as he measured on
ROMEO, Table II). DVL/IMU-like noise; 8 runs of 60 s at 20 Hz. Run from the repository root:

    python datasets/scripts/make_demo_log.py
"""

from pathlib import Path

from nnid.loop.scenarios import effect_log
from nnid.vehicle import load_vehicle

ROOT = Path(__file__).resolve().parents[2]
vehicle = load_vehicle(ROOT / "nnid/demo_data/minirov.toml")
log = effect_log(
    vehicle,
    [("thruster_installation.w.neg", 0.57)],
    duration=480.0,
    dt=0.05,
    n_experiments=8,
    speed=(0.15, 0.4),
    seed=2026,
)
out = ROOT / "nnid/demo_data/demo_minirov_heave.parquet"
log.to_parquet(out, index=False)
print(f"wrote {out} ({len(log)} rows)")
