"""Excitation signals for identification experiments.

Each signal is a small pydantic model (so configs validate it) with ``__call__(t) -> array``.
``channel`` names a generalized force (``X Y Z K M N``) or a thruster (its command). Signals on
the same channel add up. Steps and stairs, chirp, multisine (Schroeder phases), PRBS (maximum
length shift register), APRBS (random levels on random holds, for nonlinear black-box models),
Caccia's d-optimal sinusoid (eqs 13-15) and Weiss's identification
sequence (section V.B) are provided.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from nnid.physics.dofs import FORCES
from nnid.validation import StrictModel

#: slack, in periods, of a clock read at sampled times: t = k·dt is inexact, and (k·dt)/hold
#: landed just under a whole number (floor then read the period before: a PRBS at hold = dt
#: repeated 54 chips and skipped 54 in 1000 samples); the simulator reads its input samples
#: with the same rule (:func:`nnid.datasets.simulator.integrate`)
TICK_SLACK = 1e-9


def ticks(t: np.ndarray | float, period: float) -> np.ndarray:
    """Whole ``period`` s elapsed at times ``t`` (from the clock's zero), read with
    :data:`TICK_SLACK`: a time within rounding of a period's edge is in the period it begins."""
    return np.floor(np.asarray(t, dtype=np.float64) / period + TICK_SLACK).astype(int)


class _Signal(StrictModel):
    channel: str
    start: float = Field(0.0, ge=0)

    def draw(self) -> tuple | None:
        """What fixes a random signal's sequence (its kind, seed and clock), for two signals
        that would draw the same one (:func:`same_draws`); None for a deterministic signal."""
        return None

    def window(self, t: np.ndarray, duration: float | None) -> np.ndarray:
        """Where the signal acts: ``duration`` s from ``start`` (to the end of ``t`` where
        None). Its edges are read as the chips' clock is (:func:`ticks`): t = k·dt is inexact,
        and a sample within rounding of an edge fell on either side of it."""
        if duration is None:  # the start's rounding is the one to allow for
            return ticks(t - self.start, self.start or 1.0) >= 0
        return ticks(t - self.start, duration) == 0

    def top_frequency(self) -> float:
        """The highest frequency the signal is made of, Hz (0 for steps and sequences: their
        edges are sampled as they fall)."""
        return 0.0

    def top_key(self) -> str | None:
        """The key whose value is :meth:`top_frequency` (for an error to name), or None where
        the frequency is computed from several (the d-optimal sine's)."""
        return None


class Step(_Signal):
    """A step of ``amplitude`` from ``start`` for ``duration`` seconds (held forever if absent)."""

    kind: Literal["step"] = "step"
    amplitude: float
    duration: float | None = Field(None, gt=0)

    def end(self) -> float:
        return self.start + (self.duration or 0.0)

    def __call__(self, t: np.ndarray) -> np.ndarray:
        return np.where(self.window(t, self.duration), self.amplitude, 0.0)


class Stairs(_Signal):
    """Levels held ``hold`` seconds each, one after another, then zero (stair-steps)."""

    kind: Literal["stairs"] = "stairs"
    levels: list[float] = Field(min_length=1)
    hold: float = Field(gt=0)

    def end(self) -> float:
        return self.start + self.hold * len(self.levels)

    def __call__(self, t: np.ndarray) -> np.ndarray:
        k = ticks(t - self.start, self.hold)
        inside = (k >= 0) & (k < len(self.levels))
        return np.where(inside, np.asarray(self.levels)[np.clip(k, 0, len(self.levels) - 1)], 0.0)


class Chirp(_Signal):
    """Linear-frequency sweep ``offset + amplitude sin(2π(f0 τ + (f1 − f0) τ²/(2T)))``."""

    kind: Literal["chirp"] = "chirp"
    amplitude: float
    f0: float = Field(gt=0)
    f1: float = Field(gt=0)
    duration: float = Field(gt=0)
    offset: float = 0.0

    def end(self) -> float:
        return self.start + self.duration

    def top_frequency(self) -> float:
        return max(self.f0, self.f1)

    def top_key(self) -> str | None:
        return "f1" if self.f1 >= self.f0 else "f0"

    def __call__(self, t: np.ndarray) -> np.ndarray:
        tau = t - self.start
        phase = 2 * math.pi * (self.f0 * tau + (self.f1 - self.f0) * tau**2 / (2 * self.duration))
        return np.where(
            self.window(t, self.duration), self.offset + self.amplitude * np.sin(phase), 0.0
        )


class Multisine(_Signal):
    """Sum of ``n`` equal-amplitude sines on [f_min, f_max] with Schroeder phases, scaled to a
    peak of ``amplitude`` (low crest factor, flat spectrum)."""

    kind: Literal["multisine"] = "multisine"
    amplitude: float
    f_min: float = Field(gt=0)
    f_max: float = Field(gt=0)
    n: int = Field(8, ge=1, le=1000)
    duration: float = Field(gt=0)

    @model_validator(mode="after")
    def _band(self) -> Multisine:
        if self.f_max < self.f_min:
            raise ValueError("f_max must be at least f_min")
        if self.n > 1 and self.f_max == self.f_min:
            # n sines of one frequency with Schroeder phases sum to one sine, and for an even
            # n cancel (peak ~5e-15): scaled to the amplitude, rounding noise was flown,
            # broadband up to Nyquist
            raise ValueError(
                f"f_min = f_max = {self.f_min:g} Hz with n = {self.n}: n sines of one "
                "frequency are one sine at best (for an even n they cancel); expected f_max "
                "above f_min (or n = 1 for one sine)"
            )
        if self.n == 1 and self.f_max != self.f_min:
            # one sine is flown at f_min, while the Nyquist check reads f_max
            raise ValueError(
                f"n = 1 flies one sine at f_min = {self.f_min:g} Hz, not f_max = "
                f"{self.f_max:g} Hz; expected f_max equal to f_min (or n above 1 for a band)"
            )
        return self

    def end(self) -> float:
        return self.start + self.duration

    def top_frequency(self) -> float:
        return self.f_max

    def top_key(self) -> str | None:
        return "f_max"

    def __call__(self, t: np.ndarray) -> np.ndarray:
        freqs = np.linspace(self.f_min, self.f_max, self.n)
        k = np.arange(1, self.n + 1)
        phases = -math.pi * k * (k - 1) / self.n
        tau = t - self.start
        dense = np.linspace(0.0, self.duration, 20_000)
        peak = np.abs(np.sin(2 * math.pi * np.outer(dense, freqs) + phases).sum(1)).max()
        x = np.sin(2 * math.pi * np.outer(tau, freqs) + phases).sum(1) * (self.amplitude / peak)
        return np.where(self.window(t, self.duration), x, 0.0)


# Feedback taps of maximum-length Fibonacci LFSRs (bits counted from 1).
_LFSR_TAPS = {
    3: (3, 2), 4: (4, 3), 5: (5, 3), 6: (6, 5), 7: (7, 6), 8: (8, 6, 5, 4), 9: (9, 5),
    10: (10, 7), 11: (11, 9), 12: (12, 11, 10, 4), 13: (13, 12, 11, 8), 14: (14, 13, 12, 2),
    15: (15, 14), 16: (16, 15, 13, 4),
}  # fmt: skip


def mls(order: int, seed: int = 1) -> np.ndarray:
    """One period (2^order − 1 chips) of a maximum-length sequence of ±1."""
    if order not in _LFSR_TAPS:
        raise ValueError(f"PRBS order must be in {min(_LFSR_TAPS)}..{max(_LFSR_TAPS)}")
    n = 2**order - 1
    state = (seed % n) + 1
    taps = _LFSR_TAPS[order]
    out = np.empty(n)
    for i in range(n):
        out[i] = 1.0 if state & 1 else -1.0
        bit = 0
        for tap in taps:
            bit ^= (state >> (order - tap)) & 1
        state = (state >> 1) | (bit << (order - 1))
    return out


class PRBS(_Signal):
    """Pseudo-random binary sequence ``offset ± amplitude`` switching on a clock of ``hold`` s.

    ``seed`` picks the shift register's start state. It is the signal's own (default 1 for
    every PRBS, not the simulate config's ``seed``, which seeds the sensor noise only): two
    PRBS of one experiment on their defaults fly the same chips (:func:`same_draws`).
    """

    kind: Literal["prbs"] = "prbs"
    amplitude: float
    hold: float = Field(gt=0)
    duration: float = Field(gt=0)
    order: int = Field(7, ge=3, le=16)
    seed: int = Field(1, ge=0)
    offset: float = 0.0

    def end(self) -> float:
        return self.start + self.duration

    def draw(self) -> tuple | None:
        # the register's start state is the seed modulo the period (:func:`mls`)
        return (self.kind, self.order, self.seed % (2**self.order - 1), self.hold, self.start)

    def __call__(self, t: np.ndarray) -> np.ndarray:
        chips = mls(self.order, self.seed)
        k = ticks(t - self.start, self.hold) % chips.size
        x = self.offset + self.amplitude * chips[k]
        return np.where(self.window(t, self.duration), x, 0.0)


class APRBS(_Signal):
    """Amplitude-modulated PRBS: levels drawn uniformly on ``offset ± amplitude``, each held a
    time drawn uniformly on [``hold_min``, ``hold_max``] s, from a seeded generator.

    A binary PRBS shows a nonlinear model two levels only; a black-box model (NARX, neural
    state space) must see the whole operating range and, on several channels at once, the
    combinations of inputs it will meet (Nelles, *Nonlinear System Identification*, 2nd ed.,
    section 19.7). Holds at least as long as the slowest time constant show the steady states.

    ``seed`` is the signal's own (default 0 for every APRBS, not the simulate config's
    ``seed``, which seeds the sensor noise only): two APRBS of one experiment with the same
    seed and holds fly the same sequence, scaled (:func:`same_draws`).
    """

    kind: Literal["aprbs"] = "aprbs"
    amplitude: float = Field(gt=0)
    hold_min: float = Field(gt=0)
    hold_max: float = Field(gt=0)
    duration: float = Field(gt=0)
    seed: int = Field(0, ge=0)
    offset: float = 0.0

    @model_validator(mode="after")
    def _holds(self) -> APRBS:
        if self.hold_max < self.hold_min:
            raise ValueError("hold_max must be at least hold_min")
        if self.duration / self.hold_min > 1e7:  # one level drawn per hold: memory, not a run
            raise ValueError(
                f"{self.duration:g} s in holds of {self.hold_min:g} s is over 1e7 levels"
            )
        return self

    def end(self) -> float:
        return self.start + self.duration

    def draw(self) -> tuple | None:
        # the holds are drawn first, as many as the duration needs, then the levels
        count = math.ceil(self.duration / self.hold_min)
        return (self.kind, self.seed, self.hold_min, self.hold_max, count, self.start)

    def switches(self) -> tuple[np.ndarray, np.ndarray]:
        """Switching times (from ``start``) and the level held from each."""
        rng = np.random.default_rng(self.seed)
        n = math.ceil(self.duration / self.hold_min) + 1
        times = np.concatenate([[0.0], np.cumsum(rng.uniform(self.hold_min, self.hold_max, n))])
        levels = self.offset + self.amplitude * rng.uniform(-1.0, 1.0, times.size)
        return times, levels

    def __call__(self, t: np.ndarray) -> np.ndarray:
        times, levels = self.switches()
        k = np.searchsorted(times, t - self.start, side="right") - 1
        x = levels[np.clip(k, 0, levels.size - 1)]
        return np.where(self.window(t, self.duration), x, 0.0)


def same_draws(signals: list[_Signal]) -> list[list[int]]:
    """Groups of the indices of ``signals`` that draw the same random sequence (same kind,
    seed and clock: :meth:`_Signal.draw`) on more than one channel: their inputs are collinear
    (correlation ±1, whatever their amplitudes and offsets), and a regression cannot separate
    the channels' effects. Each group in the order of its first signal."""
    groups: dict[tuple, list[int]] = {}
    for j, signal in enumerate(signals):
        key = signal.draw()
        if key is not None:
            groups.setdefault(key, []).append(j)
    return [g for g in groups.values() if len({signals[j].channel for j in g}) > 1]


class Sine(_Signal):
    """``offset + amplitude sin(2π f (t − start))`` for ``duration`` seconds."""

    kind: Literal["sine"] = "sine"
    amplitude: float
    frequency: float = Field(gt=0)
    duration: float = Field(gt=0)
    offset: float = 0.0

    def end(self) -> float:
        return self.start + self.duration

    def top_frequency(self) -> float:
        return self.frequency

    def top_key(self) -> str | None:
        return "frequency"

    def __call__(self, t: np.ndarray) -> np.ndarray:
        x = self.offset + self.amplitude * np.sin(2 * math.pi * self.frequency * (t - self.start))
        return np.where(self.window(t, self.duration), x, 0.0)


def doptimal_frequency(
    inertia: float,
    k_linear: float,
    k_quadratic: float,
    force: float,
    eta: float = 1.0,
    bias: float = 0.0,
) -> float:
    """Caccia eqs 13-14: ω_opt = 1 / (√3 t_c), t_c = m_ξ / k_L, k_L = k_ξ + 2 k_ξ|ξ| |ξ*|.

    ξ* is the steady speed under the mean force: k ξ* + k₂ ξ*|ξ*| = η φ̂ + ν̄ (Caccia's drag
    coefficients are positive: the drag force is −k ξ − k₂ ξ|ξ|). Returns rad/s.
    """
    drive = eta * force + bias
    if k_quadratic > 0:
        speed = (-k_linear + math.sqrt(k_linear**2 + 4 * k_quadratic * abs(drive))) / (
            2 * k_quadratic
        )
    else:
        speed = abs(drive) / k_linear
    k_l = k_linear + 2 * k_quadratic * speed
    return 1.0 / (math.sqrt(3.0) * inertia / k_l)


class DOptimalSine(_Signal):
    """Caccia's d-optimal sinusoid (eq. 15): φⁿ(t) = φ̂ + Δφ sin(ω_opt t), with ω_opt from a
    first-step estimate of inertia and drag (eqs 13-14) and Δφ ≤ |φ̂| so the thrust never
    reverses (no propeller inversion)."""

    kind: Literal["doptimal_sine"] = "doptimal_sine"
    offset: float
    amplitude: float = Field(gt=0)
    inertia: float = Field(gt=0)
    k_linear: float = Field(ge=0)
    k_quadratic: float = Field(0.0, ge=0)
    eta: float = Field(1.0, gt=0)
    duration: float = Field(gt=0)

    @model_validator(mode="after")
    def _no_inversion(self) -> DOptimalSine:
        if self.amplitude > abs(self.offset):
            raise ValueError("amplitude must not exceed |offset|: the thrust would reverse")
        if self.k_linear == 0 and self.k_quadratic == 0:
            raise ValueError("k_linear or k_quadratic must be positive")
        return self

    def frequency(self) -> float:
        """ω_opt in rad/s."""
        return doptimal_frequency(
            self.inertia, self.k_linear, self.k_quadratic, self.offset, self.eta
        )

    def end(self) -> float:
        return self.start + self.duration

    def top_frequency(self) -> float:
        return self.frequency() / (2 * math.pi)

    def __call__(self, t: np.ndarray) -> np.ndarray:
        x = self.offset + self.amplitude * np.sin(self.frequency() * (t - self.start))
        return np.where(self.window(t, self.duration), x, 0.0)


_DOF_NAMES = {"X": "surge", "Y": "sway", "Z": "heave", "K": "roll", "M": "pitch", "N": "yaw"}
# Weiss V.B: after the decoupled runs, the coupled pairs and triples that excite roll and pitch
# through coupling (surge-heave identifies pitch, eqs 105-108).
_WEISS_COUPLED = ("XY", "XZ", "XN", "YZ", "YN", "ZN", "XYZ", "XYN")


class WeissSequence(StrictModel):
    """Weiss's identification sequence (section V.A-V.B, conclusions): stair-step runs in the
    decoupled DOFs surge, sway, heave, roll, yaw, in that order, then the coupled pairs and
    triples surge-sway, surge-heave, surge-yaw, sway-heave, sway-yaw, heave-yaw,
    surge-sway-heave and surge-sway-yaw.

    A run lasts ``hold`` × (len(``levels``) + 1) s. Its first DOF (the only one of a decoupled
    run) holds every one of ``levels`` (fractions of the DOF's ``amplitude``: by default both
    signs, several steady speeds) for ``hold`` s each, then coasts for ``hold`` s (free decay
    shows the inertia). In coupled runs the second and third DOF switch on slower clocks (1.37
    and 1.71 × ``hold``) so that their inputs are not collinear; in the same run length they
    hold only the levels whose hold ends a whole hold before the run's end: with the default
    five levels, the second DOF flies the first three (0.3, 0.65, 1: Y at 9, 19.5 and 30 N in
    surge-sway) and the third the first two (0.3, 0.65: N at 1.2 and 2.6 N m in
    surge-sway-yaw), so they see one direction only. (Kept as flown: the Seamor configs'
    data and the numbers pinned on them come from it.)
    """

    kind: Literal["weiss"] = "weiss"
    amplitudes: dict[str, float] = Field(
        default_factory=lambda: {"X": 30.0, "Y": 30.0, "Z": 30.0, "K": 4.0, "N": 4.0}
    )
    levels: list[float] = Field(default_factory=lambda: [0.3, 0.65, 1.0, -0.5, -1.0], min_length=1)
    hold: float = Field(8.0, gt=0)
    coupled: list[str] = Field(default_factory=lambda: list(_WEISS_COUPLED))

    @model_validator(mode="after")
    def _channels(self) -> WeissSequence:
        for ch in self.amplitudes:
            if ch not in FORCES:
                raise ValueError(f"amplitudes: '{ch}' is not one of {', '.join(FORCES)}")
        for combo in self.coupled:
            missing = [c for c in combo if c not in self.amplitudes]
            if missing:
                raise ValueError(f"coupled run '{combo}' needs amplitudes for {missing}")
        return self

    def experiments(self) -> list[dict]:
        """Experiment definitions (``nnid.config.Experiment`` fields) in Weiss's order."""
        runs = []
        for ch in FORCES:
            if ch in self.amplitudes:
                runs.append(self._run(_DOF_NAMES[ch], ch))
        for combo in self.coupled:
            runs.append(self._run("-".join(_DOF_NAMES[c] for c in combo), *combo))
        return runs

    def _run(self, name: str, *channels: str) -> dict:
        signals = []
        duration = self.hold * (len(self.levels) + 1)
        for k, ch in enumerate(channels):
            hold = duration / (len(self.levels) + 1) * (1.0, 1.37, 1.71)[k]
            # never more than len(levels), so ``self.levels * 2`` never reads its second copy
            # (the docstring says what is flown; kept: the Seamor configs' data come from it)
            n_levels = max(1, int((duration - hold) // hold))
            levels = [(self.levels * 2)[i] * self.amplitudes[ch] for i in range(n_levels)]
            signals.append({"kind": "stairs", "channel": ch, "levels": levels, "hold": hold})
        return {"name": name, "duration": duration, "signals": signals}
