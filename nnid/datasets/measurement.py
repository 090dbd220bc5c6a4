"""Sensor models that turn true states into logged columns.

- ``none``: exact pose (continuous angles), body velocities and accelerations.
- ``mocap``: motion-capture pose only, white noise on position and attitude (Weiss V.A.2: VICON
  at 100 Hz), angles wrapped to ±π as a real tracker reports them.
- ``dvl_imu``: DVL body velocity and gyro rates with white noise and constant bias, depth from
  pressure and AHRS attitude (McCarter 2.5); no horizontal position.
"""

from __future__ import annotations

from typing import Annotated, Literal

import numpy as np
from pydantic import Field, model_validator

from nnid.datasets.log import (
    ACCELERATION,
    MAX_ANGLE,
    MAX_DISTANCE,
    MAX_SPEED,
    POSE,
    VELOCITY,
    wrap_angle,
)
from nnid.validation import StrictModel


def relative_noise(log, sources: dict[str, str], fraction: float, rng: np.random.Generator) -> None:
    """In place: ``log[column] = log[source] + white noise`` of ``fraction`` times the source's
    standard deviation, per ``{column: source}`` in order (Weiss V.B's "low power" noise on
    true signals; a column may be its own source)."""
    for column, source in sources.items():
        x = log[source]
        log[column] = x + rng.normal(0, fraction * x.std(), len(log))


#: the noise fields each kind of measurement reads
USES = {
    "none": (),  # the truth: every level is left unread
    "mocap": ("position_noise", "angle_noise"),
    "dvl_imu": ("velocity_noise", "velocity_bias", "gyro_noise", "gyro_bias", "depth_noise",
                "attitude_noise"),
}  # fmt: skip


#: a sensor's noise level or bias, bounded by the log's bound on what it measures: one beyond
#: every value a log may hold measures nothing, and the log it made was refused as the --out file
Length = Annotated[float, Field(ge=0, le=MAX_DISTANCE)]
Angle = Annotated[float, Field(ge=0, le=MAX_ANGLE)]
Speed = Annotated[float, Field(ge=0, le=MAX_SPEED)]
Bias = Annotated[float, Field(ge=-MAX_SPEED, le=MAX_SPEED)]


class Measurement(StrictModel):
    """Noise levels are standard deviations in SI units; biases are constant per run."""

    kind: Literal["none", "mocap", "dvl_imu"] = "none"
    position_noise: Length = 0.001
    angle_noise: Angle = 0.002
    velocity_noise: Speed = 0.005
    velocity_bias: list[Bias] = Field(
        default_factory=lambda: [0.0, 0.0, 0.0], min_length=3, max_length=3
    )
    gyro_noise: Speed = 0.002  # rad/s: bounded as a log's angular rates
    gyro_bias: list[Bias] = Field(
        default_factory=lambda: [0.0, 0.0, 0.0], min_length=3, max_length=3
    )
    depth_noise: Length = 0.01
    attitude_noise: Angle = 0.005
    truth: bool = False

    @model_validator(mode="after")
    def _used(self) -> Measurement:
        # a noise level of the other kind's sensors would be ignored without a word; "none"
        # keeps its levels unread (switching a noisy config to the truth is one edit)
        stray = sorted(set(self.model_fields_set) - {"kind", "truth", *USES[self.kind]})
        if stray and "kind" not in self.model_fields_set:  # no kind: the levels read nothing
            raise ValueError(
                f"{', '.join(stray)} set without a kind: the default kind 'none' logs the exact "
                "truth and reads no noise level (give kind: mocap, dvl_imu, ...)"
            )
        if stray and self.kind != "none":
            uses = ", ".join(USES[self.kind])
            raise ValueError(f"kind {self.kind!r} does not use {', '.join(stray)} (it uses {uses})")
        return self

    def columns(
        self, states: np.ndarray, accelerations: np.ndarray, rng: np.random.Generator
    ) -> dict[str, np.ndarray]:
        """Logged columns for true states ``[N, ≥12]`` and accelerations ``[N, 6]``."""
        n = states.shape[0]
        pose, vel = states[:, 0:6], states[:, 6:12]
        out: dict[str, np.ndarray] = {}
        if self.kind == "none":
            out.update({c: pose[:, i] for i, c in enumerate(POSE)})
            out.update({c: vel[:, i] for i, c in enumerate(VELOCITY)})
            out.update({c: accelerations[:, i] for i, c in enumerate(ACCELERATION)})
        elif self.kind == "mocap":
            noise = np.concatenate(
                [
                    rng.normal(0, self.position_noise, (n, 3)),
                    rng.normal(0, self.angle_noise, (n, 3)),
                ],
                1,
            )
            meas = pose + noise
            meas[:, 3:6] = wrap_angle(meas[:, 3:6])
            out.update({c: meas[:, i] for i, c in enumerate(POSE)})
        else:
            lin = (
                vel[:, 0:3]
                + np.asarray(self.velocity_bias)
                + rng.normal(0, self.velocity_noise, (n, 3))
            )
            ang = vel[:, 3:6] + np.asarray(self.gyro_bias) + rng.normal(0, self.gyro_noise, (n, 3))
            att = wrap_angle(pose[:, 3:6] + rng.normal(0, self.attitude_noise, (n, 3)))
            out["z"] = pose[:, 2] + rng.normal(0, self.depth_noise, n)
            out.update({c: att[:, i] for i, c in enumerate(("phi", "theta", "psi"))})
            out.update({c: lin[:, i] for i, c in enumerate(("u", "v", "w"))})
            out.update({c: ang[:, i] for i, c in enumerate(("p", "q", "r"))})
        if self.truth:
            out.update({f"true_{c}": pose[:, i] for i, c in enumerate(POSE)})
            out.update({f"true_{c}": vel[:, i] for i, c in enumerate(VELOCITY)})
        return out
