"""Thrusters: thrust curves, allocation from geometry, and installation coefficients.

- Thrust curves: an odd-symmetric polynomial in the command (Weiss's PWM fit, eq. 10), Caccia's
  τ = c_V V|V| (eq. 6, c_V of its own for reverse thrust), or a measured, possibly asymmetric
  table.
- Allocation: τ = B f with column i of B = [dᵢ; rᵢ × dᵢ] for a thruster at rᵢ pushing along dᵢ
  (reproduces Weiss eqs 4-9 and Caccia's B_H, B_V).
- Installation: Caccia eq. 3, the effective generalized force is η_ξ times the nominal one, with
  η depending on the sign of the nominal force in that DOF.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from nnid.physics.dofs import FORCES


@dataclass(frozen=True)
class ThrustCurve:
    """Command -> thrust [N]. ``kind`` is 'poly', 'signed_quadratic' or 'table'."""

    kind: str
    coeffs: tuple[float, ...] = ()
    k: float = 0.0
    k_neg: float | None = None  # the reverse coefficient (Caccia eq. 6); None: k
    cmd: tuple[float, ...] = ()
    thrust: tuple[float, ...] = ()

    def __call__(self, command: np.ndarray) -> np.ndarray:
        command = np.asarray(command, dtype=np.float64)
        if self.kind == "poly":
            mag = np.abs(command)
            out = np.zeros_like(command)
            for power, c in enumerate(self.coeffs):
                out = out + c * mag**power
            return np.sign(command) * out
        if self.kind == "signed_quadratic":
            k = self.k if self.k_neg is None else np.where(command >= 0, self.k, self.k_neg)
            return k * command * np.abs(command)
        if self.kind == "table":
            return np.interp(command, self.cmd, self.thrust)
        raise ValueError(f"unknown thrust curve kind '{self.kind}'")


def allocation_matrix(positions: Tensor, directions: Tensor) -> Tensor:
    """B ``[6, n]`` from thruster positions and unit directions ``[n, 3]`` (body frame)."""
    positions = torch.as_tensor(positions, dtype=torch.float64)
    directions = torch.as_tensor(directions, dtype=torch.float64)
    moments = torch.linalg.cross(positions, directions)
    return torch.cat([directions, moments], -1).T


def apply_installation(tau, eta_pos, eta_neg, tau_neg=None):
    """Caccia eq. 3: τ_eff = η⁺ τ where τ ≥ 0, η⁻ τ where τ < 0, per DOF (arrays or tensors).

    With ``tau_neg``, ``tau`` = L[τ] and ``tau_neg`` = L[τ⁻] are the nominal force and its
    negative part τ⁻ = min(τ, 0) through the actuator lag L = 1/(T s + 1), and the result is
    the installed force through the lag, L[η(sign τ) τ] = η⁺ L[τ⁺] + η⁻ L[τ⁻] = η⁺ L[τ] +
    (η⁻ − η⁺) L[τ⁻] (L is linear): the installation acts on the force commanded, before the
    lag, as the simulator and :func:`~nnid.evaluation.prediction.predict_states` apply it.
    η(sign L[τ]) L[τ] would differ wherever τ changes sign within a lag time. Written with
    η⁻ − η⁺ so that a DOF of equal coefficients gets η L[τ] to the last bit, as without it.
    """
    if tau_neg is not None:
        return eta_pos * tau + (eta_neg - eta_pos) * tau_neg
    if isinstance(tau, torch.Tensor):
        return torch.where(tau >= 0, eta_pos * tau, eta_neg * tau)
    return np.where(tau >= 0, eta_pos * tau, eta_neg * tau)


def apply_deadband(signal: np.ndarray, width: float) -> np.ndarray:
    """Zero output while |signal| ≤ width, unchanged outside: a thruster that does not spin up."""
    signal = np.asarray(signal, dtype=np.float64)
    return np.where(np.abs(signal) <= width, 0.0, signal)


def force_deadband(vehicle) -> float:
    """The deadband of generalized forces, as a log or an autopilot gives them: a vehicle
    without thrusters has its commands in them; a thruster vehicle's deadband is in command
    units, and its forces are past it (36 µs of PWM zeroed 36 N of every force)."""
    return 0.0 if vehicle.thrusters else float(vehicle.deadband)


class Actuation:
    """Inputs to generalized forces for a vehicle: thruster commands through curves and
    allocation, or generalized forces directly; then deadband and installation (Caccia eq. 3).

    ``channels`` are the thruster names, or ``X Y Z K M N`` for a vehicle without thrusters.
    """

    def __init__(self, vehicle) -> None:
        self.thrusters = list(vehicle.thrusters)
        self.eta_pos, self.eta_neg = vehicle.installation_vectors()
        self.deadband = float(vehicle.deadband)
        if self.thrusters:
            self.channels = tuple(t.name for t in self.thrusters)
            self.curves = [ThrustCurve(**t.curve.model_dump()) for t in self.thrusters]
            self.matrix = allocation_matrix(
                [t.position for t in self.thrusters], [t.direction for t in self.thrusters]
            ).numpy()
        else:
            self.channels = FORCES
            self.curves = []
            self.matrix = np.eye(6)

    def nominal(self, inputs: np.ndarray, deadband: bool = False) -> np.ndarray:
        """Nominal generalized force ``[N, 6]`` for inputs ``[N, n_channels]``: what a vehicle
        file that knows only the thrust curves and geometry predicts (with ``deadband``, the
        vehicle's deadband applied to the inputs first; never the installation)."""
        inputs = np.asarray(inputs, dtype=np.float64)
        if deadband:
            inputs = apply_deadband(inputs, self.deadband)
        return self._force(inputs, ideal=True)

    def applied(self, inputs: np.ndarray) -> np.ndarray:
        """Generalized force the vehicle feels: deadband and installation coefficients applied."""
        return self._force(np.asarray(inputs, dtype=np.float64), ideal=False)

    def thrusts(self, inputs: np.ndarray) -> np.ndarray:
        """Thrust of each thruster ``[N, n]`` [N] for commands ``[N, n]``: each command clipped
        to its thruster's range, then through its curve (no deadband, no installation)."""
        inputs = np.asarray(inputs, dtype=np.float64)
        cols = []
        for k, (thruster, curve) in enumerate(zip(self.thrusters, self.curves, strict=True)):
            lo = -np.inf if thruster.cmd_min is None else thruster.cmd_min
            hi = np.inf if thruster.cmd_max is None else thruster.cmd_max
            cols.append(curve(np.clip(inputs[:, k], lo, hi)))
        return np.stack(cols, -1) if cols else np.zeros((inputs.shape[0], 0))

    def _force(self, inputs: np.ndarray, ideal: bool) -> np.ndarray:
        if not ideal:
            inputs = apply_deadband(inputs, self.deadband)
        tau = self.thrusts(inputs) @ self.matrix.T if self.thrusters else inputs
        return tau if ideal else apply_installation(tau, self.eta_pos, self.eta_neg)
