"""The vehicle file (TOML contract of ARCHITECTURE.md): schema, validation, presets.

SI units and Fossen's sign conventions. Unknown values are simply absent. Besides the contract,
a vehicle may declare plant extras that the simulator's injected effects also use: a steady
water current (NED), a constant external force, a first-order actuator lag and a deadband.
"""

from __future__ import annotations

import math
import sys
import tomllib
import warnings
from collections.abc import Sequence
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import Field, ValidationInfo, field_validator, model_validator

# a constant external force and a commanded speed obey the log's bounds
from nnid.datasets.log import MAX_FORCE, MAX_SPEED
from nnid.errors import NnidInputError
from nnid.physics.added_mass import mirrored_key, parse_added_mass_key
from nnid.physics.dofs import DOFS
from nnid.validation import (
    StrictModel,
    control_character,
    read_toml,
    refuse_other_file,
    repeated,
    validated,
    visible_line,
)

PRESETS = ("seamor", "vlbv300", "romeo", "vt690", "bluerov2_heavy")

Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]
Vec6 = Annotated[list[float], Field(min_length=6, max_length=6)]


#: beyond these a value is a unit slip or a typo, not a vehicle (the largest AUVs weigh tens of
#: tonnes and measure tens of metres)
MAX_MASS = 1e6  # kg
MAX_OFFSET = 100.0  # m, a position on the vehicle
MAX_COEFFICIENT = 1e9  # any added-mass or damping coefficient, SI
MAX_LAG = 60.0  # s, a thruster's first-order lag: longer is no thruster
MAX_CURRENT = 10.0  # m/s, a water current (the fastest tidal races run at about 5)
Offset = Annotated[
    list[Annotated[float, Field(ge=-MAX_OFFSET, le=MAX_OFFSET)]], Field(min_length=3, max_length=3)
]


#: a thrust-curve number beyond MAX_COEFFICIENT (N per unit of command, or N in a table) is a
#: unit slip: the allocation, the residual and the monitor's calibration would overflow on it
CurveNumber = Annotated[float, Field(ge=-MAX_COEFFICIENT, le=MAX_COEFFICIENT)]


#: the validation context of a vehicle whose thrust curves were read before: a saved model's
#: (:func:`saved_vehicle`), or a copy of a vehicle with other values set. Its curves are kept as
#: they were, one of no thrust included (an nnid before the refusal saved such a model), and so
#: are its rigid body (:meth:`Vehicle._rigid_body`) and its length (a length in cm,
#: :meth:`Vehicle._length_in_metres`), refused in new input only: a fit's r_g, a
#: payload or a saved model is said where it is flown (simulator.check_mass_matrix) or fitted
KEEP_CURVES: dict[str, Any] = {"keep_curves": True}
#: the validation context of a saved model's vehicle (:func:`saved_vehicle`): as
#: :data:`KEEP_CURVES`, and its thruster directions kept bit for bit (normalised when first
#: read; normalising again moves the last bit of a third of them, [1, 1, 0] read 0.7071...75
#: then ...76, and the loaded model's allocation, so its predictions, were not the saved one's)
AS_SAVED: dict[str, Any] = {**KEEP_CURVES, "as_saved": True}


def _makes_thrust(values: list[float], what: str, info: ValidationInfo) -> list[float]:
    """``values`` unless every one is zero: such a curve gives no thrust at any command, and its
    thruster would be a column of zeros in the allocation (a typo, or a thruster to drop). A
    negative one is kept: docs/vehicle_file.md, a thrust against ``direction``. Kept under
    :data:`KEEP_CURVES` (a curve read before)."""
    if not any(values) and not (info.context or {}).get("keep_curves"):
        raise ValueError(f"{what}: no thrust at any command (give the curve, or drop the thruster)")
    return values


class PolyCurve(StrictModel):
    kind: Literal["poly"]
    coeffs: list[CurveNumber] = Field(min_length=1)

    @field_validator("coeffs")
    @classmethod
    def _thrust(cls, coeffs: list[float], info: ValidationInfo) -> list[float]:
        return _makes_thrust(coeffs, "every coefficient is 0", info)


class SignedQuadraticCurve(StrictModel):
    """thrust = k c|c| for c ≥ 0, k_neg c|c| for c < 0 (Caccia eq. 6; c_V = 1.02 forward,
    1.09 N/V² reverse, L217). ``k_neg`` None: k (a symmetric thruster)."""

    kind: Literal["signed_quadratic"]
    k: CurveNumber
    k_neg: CurveNumber | None = None

    @field_validator("k")
    @classmethod
    def _thrust(cls, k: float, info: ValidationInfo) -> float:
        return _makes_thrust([k], "k = 0", info)[0]

    @model_validator(mode="after")
    def _same_way(self) -> SignedQuadraticCurve:
        # k_neg is a magnitude like k (Caccia's 1.09, not −1.09): of the other sign, or 0, the
        # thrust would not turn with the command, and no curve inverse (allocation) exists
        if self.k_neg is not None and not self.k_neg * self.k > 0:
            raise ValueError(
                f"k_neg = {self.k_neg:g} must have the sign of k = {self.k:g}: the thrust at "
                "a negative command c is k_neg c|c| (Caccia eq. 6, reverse c_V = 1.09 given as "
                "1.09)"
            )
        return self


class TableCurve(StrictModel):
    kind: Literal["table"]
    cmd: list[float] = Field(min_length=2)
    thrust: list[CurveNumber] = Field(min_length=2)

    @field_validator("thrust")
    @classmethod
    def _thrust(cls, thrust: list[float], info: ValidationInfo) -> list[float]:
        return _makes_thrust(thrust, "every thrust is 0", info)

    @model_validator(mode="after")
    def _check(self) -> TableCurve:
        if len(self.cmd) != len(self.thrust):
            raise ValueError("cmd and thrust must have the same length")
        if np.any(np.diff(self.cmd) <= 0):
            raise ValueError("cmd must be strictly increasing")
        return self


Curve = Annotated[PolyCurve | SignedQuadraticCurve | TableCurve, Field(discriminator="kind")]


class Thruster(StrictModel):
    name: str = Field(pattern=r"^[A-Za-z0-9_]+$")
    position: Offset
    direction: Vec3
    curve: Curve
    cmd_min: float | None = None
    cmd_max: float | None = None

    @model_validator(mode="after")
    def _range(self) -> Thruster:
        if self.cmd_min is not None and self.cmd_max is not None and self.cmd_min >= self.cmd_max:
            raise ValueError(f"cmd_min ({self.cmd_min:g}) must be below cmd_max ({self.cmd_max:g})")
        return self

    @field_validator("direction")
    @classmethod
    def _unit(cls, d: list[float], info: ValidationInfo) -> list[float]:
        norm = math.sqrt(sum(x * x for x in d))
        if (info.context or {}).get("as_saved") and abs(norm - 1.0) <= 4 * sys.float_info.epsilon:
            return d  # normalised when first read: kept bit for bit (a hand-edited one is not)
        if not 0 < norm < math.inf:
            # hypot scales before it squares: the sum of squares overflowed [1e300, 1e300, 0]
            # to inf (a direction of zeros, a thruster that pushed nowhere) and underflowed
            # [1e-300, 0, 0] to 0; components are finite here (StrictModel), so only [0, 0, 0]
            # is refused. Only there: every other direction keeps its last bits
            norm = math.hypot(*d)
        if not norm > 0:
            raise ValueError("direction must be a non-zero vector")
        return [x / norm for x in d]


class Damping(StrictModel):
    model: str | None = None
    # McCarter's commanded forward speed, compared with the speed U >= 0 in eta = u_c / U: not
    # negative, and within the speeds a log may hold (a bound on corrupt data)
    u_c: float = Field(0.0, ge=0, le=MAX_SPEED)  # m/s
    coefficients: dict[str, float] = Field(default_factory=dict)

    @field_validator("model")
    @classmethod
    def _known(cls, name: str | None) -> str | None:
        from nnid.physics.damping_library import mask_terms

        if name is not None:
            mask_terms(name)
        return name

    @field_validator("coefficients")
    @classmethod
    def _keys(cls, coefficients: dict[str, float]) -> dict[str, float]:
        from nnid.physics.damping import parse_coefficient_key

        seen: dict[tuple[str, str], str] = {}
        for key, value in coefficients.items():
            other = seen.setdefault(parse_coefficient_key(key), key)
            if other != key:  # two spellings of one term: the last one read would win silently
                raise ValueError(
                    f"'{other}' and '{key}' are the same coefficient "
                    f"({':'.join(parse_coefficient_key(key))}): give it once"
                )
            _not_absurd(key, value)
        return coefficients


def _not_absurd(key: str, value: float) -> None:
    if abs(value) > MAX_COEFFICIENT:
        raise ValueError(f"'{key}' = {value:g} is beyond {MAX_COEFFICIENT:g}: a unit slip?")


#: the share by which the largest principal moment may exceed the sum of the other two before
#: the inertia is refused (rounding of a published tensor: a thin disc has I_z = I_x + I_y)
TRIANGLE_TOLERANCE = 1e-3


def _inertia_of_a_body(inertia: np.ndarray) -> None:
    """Refuse principal moments that break the triangle inequality I₁ ≤ I₂ + I₃ beyond
    :data:`TRIANGLE_TOLERANCE`. No body's do, about any point: in the principal frame
    I₂ + I₃ − I₁ = 2 Σ m x₁² ≥ 0 (I_o of McCarter eq. 2.21 is a sum of m(|r|² 1 − r rᵀ)); a
    typo in one moment, or moments of two different sources, break it."""
    principal = np.linalg.eigvalsh(inertia)
    if principal.max() > (1 + TRIANGLE_TOLERANCE) * (principal.sum() - principal.max()):
        moments = ", ".join(f"{m:.4g}" for m in principal)
        raise NnidInputError(
            f"the largest principal moment exceeds the sum of the other two ({moments} kg m²), "
            "which no body's does (I₂ + I₃ − I₁ = 2 Σ m x₁² ≥ 0): a typo, or moments from "
            "different sources?",
            field="inertia",
        )


def point_mass_inertia(mass: float, r: Sequence[float] | np.ndarray) -> np.ndarray:
    """−m S(r)² = m (|r|² 1 − r rᵀ): the inertia a mass ``mass`` at ``r`` adds about the body
    origin beyond its own about its centre (the parallel-axis theorem, Fossen 2011 eq. 3.37)."""
    r = np.asarray(r, dtype=float)
    return mass * (r @ r * np.eye(3) - np.outer(r, r))


def check_rigid_body(
    mass: float, r_g: Sequence[float], inertia: np.ndarray, fitted: Sequence[str] = ()
) -> None:
    """Refuse a rigid body no body can be: principal moments of I_o that break the triangle
    inequality (:func:`_inertia_of_a_body`), or M_RB not positive definite
    (:func:`_rigid_body_positive_definite`). The check of a declared vehicle, and of a fitted
    one (``fitted``: the fitted parameters among r_g's, named as the fit's cause)."""
    inertia = np.asarray(inertia, dtype=float)
    _inertia_of_a_body(inertia)
    _rigid_body_positive_definite(mass, r_g, inertia, fitted)


def _rigid_body_positive_definite(
    mass: float, r_g: Sequence[float], inertia: np.ndarray, fitted: Sequence[str] = ()
) -> None:
    """Refuse a rigid body whose M_RB = [[m 1, −m S(r_g)], [m S(r_g), I_o]] (McCarter eq.
    2.21, Weiss eq. 19) is not positive definite. Its Schur complement is I_o + m S(r_g)²,
    the inertia about the centre of gravity (parallel-axis theorem, I_o = I_CG − m S(r_g)²):
    with r_g ≠ 0 a positive definite I_o is not enough. The slip it catches: a datasheet's
    inertia about the CG declared with the origin elsewhere (at the nose, r_g = [1, 0, 0]);
    in a fit (``fitted``, the fitted r_g components), an r_g the data do not determine."""
    r = np.asarray(r_g, dtype=float)
    lever = point_mass_inertia(mass, r)
    about_cg = inertia - lever
    principal = np.linalg.eigvalsh(0.5 * (about_cg + about_cg.T))
    if principal.min() > 0:
        return
    where = f"r_g = [{', '.join(f'{v:g}' for v in r)}] m"
    moments = (
        "the rigid body's mass matrix M_RB is not positive definite: the inertia about the "
        "centre of gravity, I_CG = I_o + m S(r_g)² (parallel-axis theorem), has principal "
        f"moments {', '.join(f'{v:.4g}' for v in principal)} kg m², not all > 0"
    )
    if fitted:
        # the inertia was declared, r_g fitted: the fit is the cause, not the added mass
        raise NnidInputError(
            f"with mass {mass:g} kg at the fitted {where} ({', '.join(fitted)} fitted), "
            f"{moments}: no body has this centre of gravity with the declared inertia "
            f"{_tensor_text(inertia)} about the body origin; the data do not determine r_g "
            "(too little excitation of the DOFs it couples), fix it or excite them",
            field="r_g",
        )
    as_cg = inertia + lever  # what `inertia` should be, were the given one about the CG
    raise NnidInputError(
        f"with mass {mass:g} kg at {where}, {moments}. 'inertia' is I_o, "
        "about the body origin, not about the centre of gravity: I_o = I_CG − m S(r_g)². If "
        f"{_tensor_text(inertia)} is about the centre of gravity (a datasheet's usually is), give "
        f"inertia = {_tensor_text(as_cg)}; else check r_g (its units, or the origin it is measured "
        "from)",
        field="inertia",
    )


def _tensor_text(tensor: np.ndarray) -> str:
    """An inertia as the file writes it: ``[Ix, Iy, Iz]`` where it is diagonal, else rows."""
    if not np.any(tensor - np.diag(np.diag(tensor))):
        return "[" + ", ".join(f"{v:.4g}" for v in np.diag(tensor)) + "]"
    return "[" + ", ".join("[" + ", ".join(f"{v:.4g}" for v in row) + "]" for row in tensor) + "]"


def vehicle_name(name: str) -> str:
    """``name`` if it can label reports and saved models: a visible character, on one line. A
    line break or another control character would break a report's lines and headings."""
    return visible_line(name)


def saved_vehicle(data: dict[str, Any], source: str = "<saved model>") -> Vehicle:
    """A vehicle as a saved model holds it (:func:`vehicle_from_dict`), loaded even where it
    was saved by an nnid that let its name hold a control character (:func:`vehicle_name`
    refuses those only since): a saved model stays loadable. Each such character is written
    as its escape (a line break as ``\\n``), so that the name labels one line, and a warning
    says so; new input (a vehicle file, ``nnid vehicle --name``) is still refused. A thruster
    whose curve gives no thrust (refused in new input since, :func:`_makes_thrust`) is kept
    as saved, with a warning: the model predicts what it did, that thruster pushing nothing."""
    name = data.get("name") if isinstance(data, dict) else None
    if isinstance(name, str) and control_character(name) is not None:
        shown = "".join(repr(c)[1:-1] if control_character(c) else c for c in name)
        warnings.warn(
            f"{source}: the vehicle name {name!r} holds a control character or a line "
            "separator, which names no longer may (it would break a report's lines); loaded "
            f"as {shown!r}",
            UserWarning,
            stacklevel=2,
        )
        data = {**data, "name": shown}
    vehicle = vehicle_from_dict(data, source, context=AS_SAVED)
    for thruster in vehicle.thrusters:
        if not any(_curve_numbers(thruster.curve)):
            warnings.warn(
                f"{source}: thruster '{thruster.name}' has a thrust curve of no thrust at any "
                "command, which vehicle files no longer may; loaded as saved: it gives no thrust",
                UserWarning,
                stacklevel=2,
            )
    return vehicle


def _curve_numbers(curve: PolyCurve | SignedQuadraticCurve | TableCurve) -> list[float]:
    """The numbers :func:`_makes_thrust` checks of a curve: all zero, it gives no thrust."""
    if isinstance(curve, PolyCurve):
        return curve.coeffs
    return [curve.k] if isinstance(curve, SignedQuadraticCurve) else curve.thrust


class Vehicle(StrictModel):
    """A validated vehicle file."""

    name: str  # reports and saved models are labelled with it: see vehicle_name
    description: str = ""
    rho: float = Field(1000.0, ge=500, le=2000)  # kg/m³: water is 1000-1030
    g: float = Field(9.81, ge=9.0, le=10.5)
    length: float | None = Field(None, gt=0, le=MAX_OFFSET)
    mass: float = Field(gt=0, le=MAX_MASS)
    weight: float | None = Field(None, gt=0, le=MAX_MASS * 10.5)
    buoyancy: float | None = Field(None, ge=0, le=MAX_MASS * 10.5)
    inertia: Vec3 | Annotated[list[Vec3], Field(min_length=3, max_length=3)]
    r_g: Offset = Field(default_factory=lambda: [0.0, 0.0, 0.0])
    r_b: Offset = Field(default_factory=lambda: [0.0, 0.0, 0.0])
    added_mass: dict[str, float] = Field(default_factory=dict)
    damping: Damping = Field(default_factory=Damping)
    installation: dict[str, float] = Field(default_factory=dict)
    thrusters: list[Thruster] = Field(default_factory=list)
    current: Annotated[
        list[Annotated[float, Field(ge=-MAX_CURRENT, le=MAX_CURRENT)]],
        Field(min_length=3, max_length=3),
    ] = Field(default_factory=lambda: [0.0, 0.0, 0.0])  # m/s
    external_bias: Annotated[
        list[Annotated[float, Field(ge=-MAX_FORCE, le=MAX_FORCE)]],
        Field(min_length=6, max_length=6),
    ] = Field(default_factory=lambda: [0.0] * 6)  # N, N m
    actuator_lag: float = Field(0.0, ge=0, le=MAX_LAG)  # s
    deadband: float = Field(0.0, ge=0)

    @field_validator("name")
    @classmethod
    def _name(cls, name: str) -> str:
        return vehicle_name(name)

    @model_validator(mode="after")
    def _defaults(self) -> Vehicle:
        if self.weight is None:
            self.weight = self.mass * self.g
        if self.buoyancy is None:
            self.buoyancy = self.weight
        return self

    @field_validator("inertia")
    @classmethod
    def _positive_definite(cls, inertia: list) -> list:
        tensor = np.diag(inertia) if np.ndim(inertia) == 1 else np.asarray(inertia, float)
        if not np.allclose(tensor, tensor.T, atol=1e-9 * max(1.0, np.abs(tensor).max())):
            raise ValueError("the inertia tensor must be symmetric")
        eigenvalues = np.linalg.eigvalsh(tensor)
        if eigenvalues.min() <= 0:
            raise ValueError("the inertia tensor must be positive definite (all Ix, Iy, Iz > 0)")
        if eigenvalues.max() > MAX_COEFFICIENT:
            raise ValueError(f"inertia above {MAX_COEFFICIENT:g} kg m² is not a vehicle")
        return inertia

    @model_validator(mode="after")
    def _rigid_body(self, info: ValidationInfo) -> Vehicle:
        # new input only (KEEP_CURVES): a vehicle read before stays loadable as it was
        if not (info.context or {}).get("keep_curves"):
            check_rigid_body(self.mass, self.r_g, self.inertia_matrix())
        return self

    @field_validator("added_mass")
    @classmethod
    def _added_mass_keys(cls, added_mass: dict[str, float]) -> dict[str, float]:
        for key, value in added_mass.items():
            parse_added_mass_key(key)
            _not_absurd(key, value)
            twin = mirrored_key(key)
            if twin in added_mass and not np.isclose(added_mass[twin], value, rtol=1e-9):
                raise ValueError(
                    f"{key} = {value:g} and {twin} = {added_mass[twin]:g} differ: the added-mass "
                    "matrix is symmetric (McCarter eq. 2.33); give one of them, or equal values"
                )
        return added_mass

    @field_validator("installation")
    @classmethod
    def _installation(cls, installation: dict[str, float]) -> dict[str, float]:
        for key, value in installation.items():
            dof, _, sign = key.partition(".")
            if dof not in DOFS or sign not in ("pos", "neg"):
                raise ValueError(f"'{key}': expected '<dof>.<pos|neg>' with dof in u v w p q r")
            if not 0 < value <= 2:
                raise ValueError(f"'{key}' = {value}: an installation coefficient lies in (0, 2]")
        return installation

    @model_validator(mode="after")
    def _deadband_below_commands(self) -> Vehicle:
        # a band at least as wide as the largest command the thrusters take (or, for a vehicle
        # without thrusters, whose commands are forces, the largest force a log may hold)
        # swallows every input: the vehicle would never move
        ranges = [(t.cmd_min, t.cmd_max) for t in self.thrusters]
        if not self.thrusters:
            widest, what = MAX_FORCE, f"the largest force a log may hold ({MAX_FORCE:g} N)"
        elif all(a is not None and b is not None for a, b in ranges):
            widest = max(max(abs(a), abs(b)) for a, b in ranges)  # type: ignore[arg-type]
            what = f"the largest command of the thrusters' cmd_min and cmd_max ({widest:g})"
        else:
            return self  # command ranges not given: no bound to hold it to
        if self.deadband >= widest:
            raise NnidInputError(
                f"{self.deadband:g} is not below {what}: no command would give thrust",
                field="deadband",
            )
        return self

    @model_validator(mode="after")
    def _length_in_metres(self, info: ValidationInfo) -> Vehicle:
        # a length in cm (45 for a 0.45-m ROV) passed, and with it thruster positions and
        # centres tens of metres out (size_slips reads them against it) and a rounding arm
        # (rounding_length) 100 times too long. New input only, as _rigid_body: a model saved
        # before the refusal (its length in cm) loads as it was saved
        if (info.context or {}).get("keep_curves"):
            return self
        side = (self.mass / self.rho) ** (1 / 3)
        if self.length is not None and self.length > MAX_SLENDERNESS * side:
            raise NnidInputError(
                f"{self.length:g} m is {self.length / side:.0f} times the side of the cube of "
                f"the volume its mass displaces ({side:.3g} m: {self.mass:g} kg at rho "
                f"{self.rho:g} kg/m³), and no vehicle is more than {MAX_SLENDERNESS:g} times "
                "as long: the length is in metres (centimetres given?)",
                field="length",
            )
        return self

    @model_validator(mode="after")
    def _unique_thrusters(self) -> Vehicle:
        names = [t.name for t in self.thrusters]
        twice = repeated(names)
        if twice:
            raise ValueError(f"thruster names must be unique: {', '.join(twice)} appear twice")
        return self

    @property
    def rounding_length(self) -> float:
        """The arm by which the rounding rule puts angular quantities in linear units (rates at
        the ends of the vehicle, a moment's force): the file's ``length``, else a metre, the
        scale :data:`~nnid.evaluation.persistence.ROUNDING` assumes of a vehicle in SI units."""
        return self.length or 1.0

    def inertia_matrix(self) -> np.ndarray:
        return np.diag(self.inertia) if np.ndim(self.inertia) == 1 else np.asarray(self.inertia)

    def installation_vectors(self) -> tuple[np.ndarray, np.ndarray]:
        """(η⁺, η⁻) per DOF, 1 where not declared (Caccia eq. 3)."""
        pos, neg = np.ones(6), np.ones(6)
        for key, value in self.installation.items():
            dof, _, sign = key.partition(".")
            (pos if sign == "pos" else neg)[DOFS.index(dof)] = value
        return pos, neg


def vehicle_from_dict(
    data: dict[str, Any], source: str = "<vehicle>", context: dict[str, Any] | None = None
) -> Vehicle:
    """Validate a parsed vehicle file; raise NnidInputError naming the file and the field, and
    warn of a diagonal added mass or damping of the wrong sign (:func:`sign_slips`).
    ``context``: pydantic's validation context (:data:`KEEP_CURVES`)."""
    refuse_other_file(data, "vehicle", "a vehicle file", source)
    vehicle = validated(Vehicle, data, source, context)
    if abs(vehicle.weight - vehicle.mass * vehicle.g) > 0.1 * vehicle.mass * vehicle.g:
        warnings.warn(
            f"{source}: weight {vehicle.weight:g} N is not mass × g = "
            f"{vehicle.mass * vehicle.g:g} N (a weight in kg, or the weight in water? "
            "buoyancy is its own key)",
            stacklevel=2,
        )
    if abs(vehicle.buoyancy - vehicle.weight) > TRIM * vehicle.weight:
        warnings.warn(
            f"{source}: buoyancy {vehicle.buoyancy:g} N is {vehicle.buoyancy / vehicle.weight:.2g} "
            f"times the weight {vehicle.weight:g} N; an underwater vehicle is trimmed within "
            "a few percent of neutral (a mass in kg, or another vehicle's buoyancy?)",
            stacklevel=2,
        )
    z_g, z_b = vehicle.r_g[2], vehicle.r_b[2]
    # FRD, z down (Fossen's g(η)): K = (z_g W − z_b B) cos θ sin φ rights a roll only where
    # z_g W > z_b B (z_g > z_b at W = B); a warning, not an error: the file may hold what the
    # vehicle is
    if z_g * vehicle.weight < z_b * vehicle.buoyancy:
        where = (
            "the centre of gravity is above the centre of buoyancy"
            if z_g < z_b
            else "the buoyancy's moment outweighs the weight's"
        )
        warnings.warn(
            f"{source}: {where} (r_g z = {z_g:g} m, W = {vehicle.weight:g} N; r_b z = {z_b:g} "
            f"m, B = {vehicle.buoyancy:g} N; body z down; z_g W < z_b B): the restoring moments "
            "tip the vehicle over in roll and pitch instead of righting it (statically "
            "unstable), where underwater vehicles are trimmed bottom-heavy (z up, or r_g and "
            "r_b swapped?)",
            stacklevel=2,
        )
    for slip in [*sign_slips(vehicle), *size_slips(vehicle)]:
        warnings.warn(f"{source}: {slip}", stacklevel=2)
    return vehicle


def vehicle_copy(vehicle: Vehicle, data: dict[str, Any]) -> Vehicle:
    """A vehicle of ``vehicle``'s type from ``data``, a dump of ``vehicle`` with other values
    set (fitted parameters, a payload). Its curves are ``vehicle``'s, checked when it was read,
    so they are kept (:data:`KEEP_CURVES`): one of no thrust that a saved model kept
    (:func:`saved_vehicle`) would otherwise refuse the copy of a vehicle already accepted."""
    return type(vehicle).model_validate(data, context=KEEP_CURVES)


#: the share of its weight by which a vehicle's buoyancy may differ before a file is warned of:
#: a 113-N vehicle declared with 1000 N of buoyancy loaded without a word
TRIM = 0.5


#: without a length, a vehicle's size is bounded by this many sides of the cube of its volume
SIZE_OF_VOLUME = 5.0
#: a length beyond this many sides of the cube of its volume is refused, a unit slip: the
#: shipped vehicles lie within 6 (VT690, 2.06 m at 41.5 kg), a torpedo-shaped AUV of ten
#: diameters within 3, a 5-cm rod 2 m long within 13; one in cm is 100 times its length
MAX_SLENDERNESS = 50.0


def size_slips(vehicle: Vehicle) -> list[str]:
    """Geometry no vehicle of this size and mass has, a unit slip (cm for m, kg cm² for
    kg m²) the fit would otherwise absorb without a word (an inertia 10⁴ too large came back
    as an added mass of +1600, "significant"): a radius of gyration, a centre of gravity or
    buoyancy, or a thruster further from the origin than the vehicle is long (its ``length``,
    else :data:`SIZE_OF_VOLUME` sides of the cube of its displaced volume); a thrust table that
    stops short of the thruster's command range (commands beyond it get the table's last
    thrust), or that gives thrust at zero command. Principal moments that break the triangle
    inequality are refused (:func:`_inertia_of_a_body`)."""
    size = vehicle.length or SIZE_OF_VOLUME * (vehicle.mass / vehicle.rho) ** (1 / 3)
    what = f"the vehicle's length ({size:.3g} m)" if vehicle.length else (
        f"{SIZE_OF_VOLUME:g} sides of the cube of its volume ({size:.3g} m; no length given)"
    )  # fmt: skip
    principal = np.linalg.eigvalsh(vehicle.inertia_matrix())
    out = []
    gyration = float(np.sqrt(principal.max() / vehicle.mass))
    if gyration > size:
        out.append(f"inertia: the radius of gyration {gyration:.3g} m exceeds {what}: kg m²?")
    for key in ("r_g", "r_b"):
        reach = float(np.linalg.norm(getattr(vehicle, key)))
        if reach > size:
            out.append(f"{key} is {reach:.3g} m from the origin, beyond {what}: metres?")
    for t in vehicle.thrusters:
        reach = float(np.linalg.norm(t.position))
        if reach > size:
            out.append(f"thruster {t.name}'s position is {reach:.3g} m out, beyond {what}: metres?")
        if isinstance(t.curve, TableCurve):
            lo, hi = t.curve.cmd[0], t.curve.cmd[-1]
            short = [(k, v) for k, v in (("cmd_min", t.cmd_min), ("cmd_max", t.cmd_max))
                     if v is not None and not lo <= v <= hi]  # fmt: skip
            if short:
                out.append(
                    f"thruster {t.name}'s thrust table spans commands {lo:g} to {hi:g}, short of "
                    + ", ".join(f"its {k} {v:g}" for k, v in short)
                    + ": beyond the table a command gets the table's last thrust"
                )
            idle = float(np.interp(0.0, t.curve.cmd, t.curve.thrust))
            lo_cmd = -math.inf if t.cmd_min is None else t.cmd_min
            hi_cmd = math.inf if t.cmd_max is None else t.cmd_max
            # a command of 0 within the thruster's range (a thruster at rest) is read off the
            # table, clamped to its ends outside it (np.interp, physics.thrusters.ThrustCurve)
            if idle != 0 and lo_cmd <= 0 <= hi_cmd:
                out.append(
                    f"thruster {t.name}'s thrust table gives {idle:g} N at command 0 (of its "
                    f"commands {lo:g} to {hi:g}): a constant force along its direction while "
                    "it is at rest (a zero offset in the measured curve? give 0 N at command 0)"
                )
    return out


def sign_slips(vehicle: Vehicle) -> list[str]:
    """Diagonal hydrodynamic derivatives of the sign that adds energy, in the SNAME notation
    the vehicle file uses (Fossen: M_A = −[X_u̇ …], D = −[X_u …]): a positive X_udot makes the
    added mass negative; a positive "X:u" or "X:u*abs(u)" where the X row has only its own
    DOF's terms pushes the vehicle faster the faster it goes. A coupled row may hold a positive
    diagonal term that its cross terms outweigh (McCarter's VT690, K_{p|p|} = +0.421), so it is
    not flagged. Warnings, not errors: a fitted weak term may come out slightly positive."""
    from nnid.physics.damping import parse_coefficient_key
    from nnid.physics.dofs import FORCES

    out = []
    for key, value in vehicle.added_mass.items():
        row, col = parse_added_mass_key(key)
        if row == col and value > 0:
            out.append(f"added mass {key} = {value:g} > 0 makes the added mass negative")
    rows: dict[str, list[tuple[str, str, float]]] = {}
    for key, value in vehicle.damping.coefficients.items():
        force, term = parse_coefficient_key(key)
        rows.setdefault(force, []).append((key, term, value))
    for force, terms in rows.items():
        dof = DOFS[FORCES.index(force)]
        if all(term in (dof, f"{dof}*abs({dof})") for _, term, _ in terms):
            out += [
                f"damping '{key}' = {value:g} > 0 feeds energy into {dof} (damping is < 0)"
                for key, _, value in terms
                if value > 0
            ]
    return out


def load_vehicle(name_or_path: str | Path) -> Vehicle:
    """A preset name (``seamor``, ``vlbv300``, ``romeo``, ``vt690``) or a path to a TOML file."""
    text = str(name_or_path)
    if text in PRESETS:
        ref = resources.files("nnid.presets").joinpath(f"{text}.toml")
        return vehicle_from_dict(tomllib.loads(ref.read_text()), source=f"preset '{text}'")
    path = Path(text)
    if not path.exists() and path.suffix == "":
        raise NnidInputError(
            f"'{text}' is neither a preset ({', '.join(PRESETS)}) nor an existing file",
            source=text,
        )
    return vehicle_from_dict(read_toml(path), source=str(path))
