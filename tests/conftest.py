from __future__ import annotations

import numpy as np
import pytest
import torch

from nnid.vehicle import vehicle_from_dict


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
