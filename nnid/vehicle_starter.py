"""A starter vehicle file for one's own ROV: from a preset, or from mass, size and a layout.

What is measured (mass, size) is used as it is; the rest is an estimate that the identification
refits, and the file says so line by line: inertia of a solid cuboid about its centre (Weiss
eqs 32-34), which is the origin and the centre of gravity (the Heavy's r_g = 0; its centres
are scaled with the size, the centre of buoyancy above the CG by the Heavy's 1 cm), added
mass and damping scaled from the BlueROV2 Heavy of von Benzon et al. 2022 (added mass with the
mass, drag with the frontal areas; a rotational term with its face's area and the powers of
the arm its Prime-system divisor has: added inertia mass × arm², linear damping area × arm²,
quadratic damping area × arm³), thrusters in the Heavy's layout scaled to the size. The output
is TOML that :func:`nnid.vehicle.load_vehicle` reads; the damping keys it declares are the
structure ``nnid loop`` and ``nnid train`` refit.
"""

from __future__ import annotations

import json
from importlib import resources

from nnid.errors import NnidInputError
from nnid.physics.dofs import DOFS, FORCES
from nnid.physics.rigid_body import cuboid_inertia
from nnid.vehicle import PRESETS, load_vehicle

#: thruster layouts a starter file can have
LAYOUTS = ("heavy8", "none")
REFERENCE = "bluerov2_heavy"


def preset_text(name: str) -> str:
    """The preset's own file, comments and citations included."""
    if name not in PRESETS:
        raise NnidInputError(
            f"unknown preset; expected one of {', '.join(PRESETS)}", field="--preset"
        )
    return resources.files("nnid.presets").joinpath(f"{name}.toml").read_text()


def _vector(values) -> str:
    return "[" + ", ".join(f"{v:.4g}" for v in values) + "]"


def starter_text(
    name: str, mass: float, size: tuple[float, float, float], layout: str = "heavy8"
) -> str:
    """A commented vehicle file for a vehicle of ``mass`` (kg) and ``size`` (length, width,
    height in m) with thrusters in ``layout`` (module docstring)."""
    length, width, height = size
    if not 0 < mass <= 1e4:
        raise NnidInputError(f"mass {mass:g} kg: expected 0 < mass <= 10000", field="--mass")
    if not all(0 < s <= 20 for s in size):  # NaN fails too
        raise NnidInputError("sizes must lie in (0, 20] m: LENGTHxWIDTHxHEIGHT", field="--size")
    if mass / 1000.0 > length * width * height:
        # the file assumes a neutral vehicle: it cannot displace more water than its box
        raise NnidInputError(
            f"a neutral vehicle of {mass:g} kg displaces {mass / 1000:.3g} m^3 of water, more "
            f"than its {length * width * height:.3g} m^3 box: is the mass in kg and the size "
            "in m?",
            field="--mass",
        )
    if layout not in LAYOUTS:
        raise NnidInputError(
            f"unknown layout; expected one of {', '.join(LAYOUTS)}", field="--layout"
        )
    ref = load_vehicle(REFERENCE)
    ref_size = (0.457, 0.575, 0.254)  # BlueROV2 Heavy, Blue Robotics
    scale = [s / r for s, r in zip(size, ref_size, strict=True)]
    # frontal areas (surge: width x height, sway: length x height, heave: length x width);
    # rotations: the face swept and its arm (roll: sway face and width, pitch: heave face and
    # length, yaw: sway face and length). An element of the face at lever r moves at ω r: its
    # linear drag makes a moment ∝ r², its quadratic drag ∝ r³ and its added mass an added
    # inertia ∝ r², so a vehicle λ times the Heavy (λ³ its mass) gets λ⁴ K_p, λ⁵ K_p|p| and
    # λ⁵ K_ṗ, as Prime system I scales them (½ρUL⁴, ½ρL⁵, ½ρL⁵; Weiss Table 4). Area times
    # arm (and the mass ratio alone) gave all three λ³: at twice the size, a quarter of the
    # quadratic damping and of the added inertia, half the linear damping
    area = [scale[1] * scale[2], scale[0] * scale[2], scale[0] * scale[1]]
    face = [area[1], area[2], area[1]]
    arm = [scale[1], scale[0], scale[0]]
    mass_ratio = mass / ref.mass
    r_g = [c * s for c, s in zip(ref.r_g, scale, strict=True)]
    r_b = [c * s for c, s in zip(ref.r_b, scale, strict=True)]
    lever = r_g[2] - r_b[2]  # z down: the CB above the CG by this much
    weight = mass * 9.81
    lines = [
        f"# Starter vehicle file for {_toml_string(name)}, written by `nnid vehicle`: EDIT IT. "
        "Measured:",
        f"# mass {mass:g} kg and size {length:g} x {width:g} x {height:g} m. Everything else is",
        "# an ESTIMATE (see each line) that `nnid loop` / `nnid train` refit or test; what stays",
        "# wrong shows up as an effect in the loop report. Fossen conventions: FRD body frame,",
        "# NED world, SI units; diagonal derivatives negative (force = coefficient * term).",
        "# Format of every key: docs/vehicle_file.md.",
        f"name = {_toml_string(name)}",
        'description = "starter file from mass and size (estimates: refit before trusting)"',
        "rho = 1000.0                  # kg/m^3: 1025 in sea water",
        f"length = {length:g}",
        # 12 digits: rounded to 6, the measured mass lost digits, and a buoyancy of 4 was not
        # neutral (0.45 N of W - B at 1234.5 kg, a sink the loop would find)
        f"mass = {mass:.12g}",
        f"buoyancy = {weight:.12g}            # N, ASSUMED neutral: weigh it (W - B is identified)",
        # about the origin, as the file's inertia is: the cuboid's centre, its CG and the
        # origin are one point here (r_g below is the Heavy's, at its origin)
        f"inertia = {_vector(cuboid_inertia(mass, length, width, height))}"
        "   # kg m^2 about the origin, solid cuboid about its centre (Weiss eqs 32-34): ESTIMATE",
        # the Heavy's centres, each axis scaled with the size: its CG at the origin and its
        # CB 1 cm above it [vB22], so the restoring lever z_g - z_b scales with the height (a
        # fixed offset put a centre outside the hull of a vehicle under a few cm tall)
        f"{'r_g = ' + _vector(r_g):<29} # m, ASSUMED the {REFERENCE}'s (origin at the CG), "
        "scaled with the size",
        f"{'r_b = ' + _vector(r_b):<29} # m, ASSUMED the {REFERENCE}'s scaled: {lever:.3g} m "
        "above r_g (it rights itself; the loop tests it)",
        "",
        f"[added_mass]                  # ESTIMATE: {REFERENCE} (von Benzon 2022) x mass ratio",
        "                              # (x arm^2 for rotations)",
    ]
    for dof, force in zip(DOFS, FORCES, strict=True):
        key = f"{force}_{dof}dot"
        lever = 1.0 if dof in "uvw" else arm[DOFS.index(dof) - 3] ** 2
        lines.append(f"{key} = {ref.added_mass[key] * mass_ratio * lever:.4g}")
    lines += [
        "",
        f"[damping.coefficients]        # ESTIMATE: {REFERENCE} scaled by frontal area (x arm^2",
        "                              # linear, x arm^3 quadratic for rotations); the keys are",
        "                              # the structure that is refitted",
    ]
    for i, (dof, force) in enumerate(zip(DOFS, FORCES, strict=True)):
        if i < 3:
            lin_factor = quad_factor = area[i]
        else:
            lin_factor = face[i - 3] * arm[i - 3] ** 2
            quad_factor = face[i - 3] * arm[i - 3] ** 3
        linear = ref.damping.coefficients.get(f"{force}:{dof}", 0.0)
        quad = ref.damping.coefficients[f"{force}:{dof}*abs({dof})"]
        lines.append(f'"{force}:{dof}" = {min(linear * lin_factor, -1e-3):.4g}')
        lines.append(f'"{force}:{dof}*abs({dof})" = {quad * quad_factor:.4g}')
    if layout == "heavy8":
        lines += [
            "",
            f"# Thrusters: the {REFERENCE} layout scaled to this size, T200 curves: CHECK the",
            "# positions, directions, names and the command scale of your vehicle.",
        ]
        for t in ref.thrusters:
            pos = [p * s for p, s in zip(t.position, scale, strict=True)]
            curve = t.curve
            lines += [
                "",
                "[[thrusters]]",
                f"name = {_toml_string(t.name)}",
                f"position = {_vector(pos)}",
                f"direction = {_vector(t.direction)}",
                f'curve = {{ kind = "table", cmd = {_vector(curve.cmd)}, '
                f"thrust = {_vector(curve.thrust)} }}",
            ]
    return "\n".join(lines) + "\n"


def _toml_string(text: str) -> str:
    """``text`` as a TOML basic string: JSON's escapes (quote, backslash, newline, \\uXXXX)
    are TOML's too; DEL, which JSON leaves bare and TOML forbids, escaped as well."""
    # ensure_ascii=False: JSON escapes a character beyond the BMP (an emoji) as a surrogate
    # pair, which TOML refuses as no scalar value (a traceback from nnid vehicle --name);
    # control characters, the only ones that need escapes here, vehicle_name refuses
    return json.dumps(text, ensure_ascii=False).replace("\x7f", "\\u007f")
