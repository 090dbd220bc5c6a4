"""Persistence of excitation of a regression (Weiss eqs 93-98).

A regressor Φ is persistently exciting when α₁ I ≤ (1/N) ΦᵀΦ ≤ α₂ I for some α₁ > 0 (eq. 95):
every parameter direction is seen. The report gives the rank and condition number of ΦᵀΦ, the
smallest singular value per parameter group, and names the parameters that the data does not
excite (a regressor column that is zero) or cannot separate (it lies in a near-null direction).
Columns are scaled to unit RMS first, so the verdict does not depend on units.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from nnid.physics.dofs import DOFS
from nnid.serialization import exact_float, read_exact_float

if TYPE_CHECKING:  # the library is only called here: importing it at run time pulls in torch
    from nnid.physics.damping_library import BasisLibrary

#: a regressor column whose RMS is at most this fraction of the typical size of a regressor of
#: its whole regression (:func:`typical_size`) is rounding, not data. What this assumes: the
#: regressors of one regression, in SI units for a vehicle of metres and seconds, are of
#: comparable size (within a few decades), so a column 10⁻¹⁰ below the typical one carries no
#: measurement: float64 leaves about 2e-16 of the quantities a value is computed from (a
#: simulator's "zero" velocity is 1e-17 of its others), and 10⁻¹⁰ keeps a margin of 10⁶ above
#: that. The fraction is across columns of different units, so it is no scale-free bound: it
#: could misjudge a regression whose columns differ by ten decades in earnest (a velocity in
#: km/s beside a force in mN, or a term of a high power of a small velocity: |r|³ of r ~ 1e-4
#: rad/s is 1e-12 beside a velocity of 1 m/s) and call a measured column rounding; such a
#: regression is ill-scaled in any case. Not of the target: on data of rounding the target is
#: rounding too (X of a heave-only log), and it has other units. The targets of a regression of
#: several outputs are judged by the same rule among themselves, against their own typical
#: size, never the regressors' (SINDy's, :class:`~nnid.trainers.sindy.SparsePath`: K of a
#: surge/sway/yaw log is the Munk moments' rounding beside N, and has nothing to explain), and
#: six DOFs' targets each against its own kind's (:func:`kind_sizes`: a moment in N·m beside
#: moments, not beside forces in N); where every target is rounding, their typical size is
#: too, and none is called so. Where a
#: regression knows the motion its columns are made of (a Fossen regression, SINDy's library
#: of terms of ν), each column has its own floor instead (:func:`motion_floors`): the motion it
#: is made of at most this fraction of the log's typical motion, which is scale-free and
#: power-aware (q|q| of a real pitch rate 1e-6 of the yaw rate is data, not rounding)
ROUNDING = 1e-10

#: the factor by which :func:`motion_floors` scales the reference motion (or each part of it)
#: to read each column's power in it
POWER_PROBE = 10.0

#: the verdict on a parameter a recursive estimator's memory does not excite but earlier
#: samples of its run did: its value is learnt from data, not fitted to noise, and kept
REMEMBERED = "not excited in the estimator's memory (value remembered from earlier samples)"


@dataclass
class ExcitationReport:
    n_samples: int
    n_params: int
    rank: int
    condition: float
    singular_values: list[float]
    group_min_singular: dict[str, float]
    unexcited: list[str]
    collinear: list[str]
    warnings: list[str] = field(default_factory=list)
    #: the unexcited parameters whose regressor the fit had only in rows it left out (not
    #: finite): not measured, rather than a zero regressor; kept so that a report rebuilt from
    #: this one (:meth:`renamed`, :func:`combined_excitation`) says the same
    not_measured: list[str] = field(default_factory=list)
    #: the unexcited parameters whose values a recursive estimator learnt from samples before
    #: its memory (:data:`REMEMBERED`), kept so that a rebuilt or saved report says the same
    remembered: list[str] = field(default_factory=list)

    @property
    def persistent(self) -> bool:
        return self.rank == self.n_params and not self.unexcited

    def as_state(self) -> dict:
        """The report as strict JSON data; the condition number of a singular ΦᵀΦ is inf,
        tagged so that it reads back inf (:func:`~nnid.serialization.exact_float`)."""
        return {**asdict(self), "condition": exact_float(self.condition)}

    def renamed(self, names: Mapping[str, str]) -> ExcitationReport:
        """The same report with its parameters renamed (old name -> new; others kept), for an
        estimate whose parameters were renamed (Caccia's signs): verdicts under the old names
        would match no parameter of it."""
        unexcited = [names.get(n, n) for n in self.unexcited]
        collinear = [names.get(n, n) for n in self.collinear]
        unread = [names.get(n, n) for n in self.not_measured]
        kept = [names.get(n, n) for n in self.remembered]
        return replace(
            self,
            unexcited=unexcited,
            collinear=collinear,
            warnings=_verdict_warnings(
                unexcited, collinear, self.rank, self.n_params, unread, kept
            ),
            not_measured=unread,
            remembered=kept,
        )

    def with_remembered(
        self, remembered: Sequence[str], collinear: Sequence[str] = ()
    ) -> ExcitationReport:
        """The same report where its unexcited parameters among ``remembered`` kept a value
        learnt from earlier data (a recursive estimator's memory check: samples before the
        memory excited them): said so, not "zero regressor", whose "fitted to noise" would be
        false of a value learnt from excited data. Those among ``collinear`` (collinear over
        the whole run: earlier samples measured only their combination with others) are said
        collinear, neither remembered (no value of theirs was learnt) nor zero regressor."""
        tied = [n for n in self.unexcited if n in collinear]
        unexcited = [n for n in self.unexcited if n not in tied]
        both = self.collinear + [n for n in tied if n not in self.collinear]
        kept = [n for n in unexcited if n in remembered]
        warnings = _verdict_warnings(
            unexcited, both, self.rank, self.n_params, self.not_measured, kept
        )
        return replace(
            self, unexcited=unexcited, collinear=both, warnings=warnings, remembered=kept
        )

    @classmethod
    def from_state(cls, state: object) -> ExcitationReport:
        """Inverse of :meth:`as_state` after a JSON round trip, checked (TypeError): a file
        edited by hand is refused at loading, never a report that fails when read."""
        if not isinstance(state, dict):
            raise TypeError("the excitation report is not a mapping")

        def names(key: str) -> list[str]:
            value = state[key]
            if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
                raise TypeError(f"the excitation report's {key} is not a list of names")
            return list(value)

        def count(key: str) -> int:
            value = state[key]
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise TypeError(f"the excitation report's {key} is not a count: {value!r}")
            return value

        values, groups = state["singular_values"], state["group_min_singular"]
        if not isinstance(values, list) or not isinstance(groups, dict):
            raise TypeError("the excitation report's singular values are not numbers")
        what = "the excitation report's singular values"
        # files saved before the verdict was kept have none: their warnings still say it
        unread = names("not_measured") if "not_measured" in state else []
        kept = names("remembered") if "remembered" in state else []
        return cls(
            count("n_samples"),
            count("n_params"),
            count("rank"),
            read_exact_float(state["condition"], "the excitation report's condition"),
            [read_exact_float(v, what) for v in values],
            {str(k): read_exact_float(v, what) for k, v in groups.items()},
            names("unexcited"),
            names("collinear"),
            names("warnings"),
            unread,
            kept,
        )


#: the rows :func:`typical_size` reads at most, drawn from a longer regression
TYPICAL_ROWS = 20_000


def typical_size(columns: np.ndarray) -> float:
    """The typical size of a regressor of ``columns`` ``[N, P]``, against which a column of
    rounding is zero (:data:`ROUNDING`): the largest, over the columns, of the median |x| of
    each column's finite non-zero entries (:func:`column_sizes`). A median, as one column
    singular on a few rows (an (η − 1) term at U = 0 under a current, 1e12:
    :func:`~nnid.physics.damping_library.atoms`) must not set it; of the non-zero entries, as a
    stacked regression (a row per DOF) reads a column on its DOF's rows only; the largest over
    the columns, not their median, as most columns of a library may be rounding (the u, v, p,
    q, r terms of a heave-only log)."""
    return float(column_sizes(columns).max(initial=0.0))


def column_sizes(columns: np.ndarray) -> np.ndarray:
    """Each column's median |x| over its finite non-zero entries ``[P]`` (0 where it has none),
    of at most :data:`TYPICAL_ROWS` rows of ``columns`` ``[N, P]``: the sizes whose largest is
    :func:`typical_size`. Its rows are drawn by their count alone, so a block of a regression's
    columns on the same rows is sized as the whole regression sizes it."""
    a = np.asarray(columns)
    if a.shape[0] > TYPICAL_ROWS:  # a size within decades is all the rule needs: rows drawn
        # by a fixed local generator, not a stride, which could read one DOF's rows of a
        # stacked regression only (a median of 600,000 rows x 40 columns took 2.2 s a solve)
        keep = np.random.default_rng(0).choice(a.shape[0], TYPICAL_ROWS, replace=False)
        a = a[np.sort(keep)]
    a = np.abs(a.astype(np.float64, copy=False))
    read = np.isfinite(a) & (a > 0)
    count = read.sum(0)
    out = np.zeros(a.shape[1])
    # the columns with as many entries read medianed together, as numpy.median does each:
    # its middle entry, or the mean of the middle two, by partition (bit-identical). The
    # demo loop's floors size 4410 candidate columns of one count in one call, which a
    # median a column took 2.5-3 times as long to read
    flat = a.T[read.T]  # the entries read, column after column
    start = np.cumsum(count) - count
    for c in np.unique(count[count > 0]):
        same = np.flatnonzero(count == c)
        entries = flat[start[same, None] + np.arange(c)]
        middle = np.partition(entries, [(c - 1) // 2, c // 2], axis=-1)
        low, high = middle[:, (c - 1) // 2], middle[:, c // 2]
        out[same] = low if c % 2 else (low + high) / 2
    return out


def kind_sizes(columns: np.ndarray, to_linear: float) -> np.ndarray:
    """The typical size (:func:`typical_size`) of each column of a six-DOF quantity ``columns``
    ``[N, 6]`` by its kind ``[6]``: the linear one's (u v w, X Y Z) for the first three, the
    angular one's (p q r, K M N) for the last three, each in its own units. One number for all
    six compared a moment in N·m with forces in N, and a yaw rate with a surge speed: a real
    one of a kind that is small beside the other (a yaw-only fit's 2.5e-6 rad/s beside 0.49
    m/s) was called rounding. A kind whose size is itself rounding beside the other's (at most
    :data:`ROUNDING` of it once ``to_linear`` puts it in the other's units: a length for rates
    and angular accelerations, at the ends of the vehicle; one over it for moments, a force's
    arm) takes the other's in its own units, as a kind that never moved has no size of its own:
    its rounding (the moments of a heave-only log, 1e-17) would be its own reference, and never
    rounding."""
    linear, angular = typical_size(columns[:, :3]), typical_size(columns[:, 3:])
    if angular * to_linear <= ROUNDING * linear:
        angular = linear / to_linear
    elif linear <= ROUNDING * angular * to_linear:
        linear = angular * to_linear
    return np.repeat([linear, angular], 3)


def equation_rms(columns: np.ndarray, m: int, kept: np.ndarray | None = None) -> np.ndarray:
    """Each column's RMS over the rows of each of ``m`` equations ``[m, P]``, unweighted: the
    sizes :func:`excitation_from_gram`'s tol rule compares within an equation. ``columns``
    ``[N, P]`` stacks the equations sample-major (row i is equation i mod m, a
    :class:`~nnid.trainers.regression.Regression`'s layout); ``kept`` ``[N]``: the rows that
    count (those a fit reads), all where None. An equation without rows has RMS 0."""
    n, p = np.shape(columns)
    a = np.asarray(columns, dtype=np.float64).reshape(n // m, m, p)
    count = np.full(m, a.shape[0])
    if kept is not None and not np.all(kept):  # a view of the layout, copied only here
        k = np.asarray(kept, dtype=bool).reshape(n // m, m)
        a, count = np.where(k[:, :, None], a, 0.0), k.sum(0)
    return np.sqrt(np.einsum("nej,nej->ej", a, a) / np.maximum(count, 1)[:, None])


def rounding_floors(at_motion: np.ndarray, at_probe: np.ndarray) -> np.ndarray:
    """Each column's floor of the rounding rule from its typical size at a reference motion
    (``at_motion`` ``[P]``: the log's typical motion) and at that motion scaled by
    :data:`POWER_PROBE` (``at_probe``): the column is rounding when the motion it is made of is
    at most :data:`ROUNDING` of the reference, so its floor is ROUNDING^p × its size at the
    reference, p its power in the motion, log(at_probe / at_motion) / log(POWER_PROBE), clipped
    to [1, 3]. Why powers: a quadratic column (u|u|) of a real velocity 10⁻⁶ of the typical one
    is 10⁻¹² of its reference, and a floor of ROUNDING × reference called it rounding, where
    rounding of a velocity is ~1e-16 of it. A column of mixed powers (an added mass: ν̇ and
    C_A(ν)ν) reads a power between its parts'.

    ``at_probe`` ``[D, P]``: the sizes with each of D parts of the motion (a velocity) scaled
    by POWER_PROBE in turn; p is then the least of a column's powers in the parts it grows
    with, as a product is rounding where one of its factors is: u·w of a log whose w is
    rounding (1e-17 of u) is of power 1 in w, and by its power in the whole motion (2, a floor
    of ROUNDING²) its 1e-17 of u² read as data. ``[P]`` is one part, the whole motion.

    A column that does not grow with the motion (p < 0.5 in every part: a restoring, bias or
    thrust column, made of the pose or the inputs, which the reference motion does not change)
    or is zero at the reference motion has no floor of its own: against itself it could never
    be rounding. Its floor is ROUNDING × the largest column of the regression at the reference
    motion, as the log's typical motion is what it is measured beside: judged against the
    regression's own columns, of a log where every column is rounding (the K equation of a
    heave-only log, φ and p ~ 1e-17), nothing was, and r_b.z read -2.4e-4 ± 4.4e-4 off a target
    of rounding. NaN (the caller's scalar rule judges it) only where no column has a size at
    the reference motion. Leading axes (``at_motion`` ``[..., P]``, ``at_probe``
    ``[..., D, P]``): as many regressions, each its own largest column."""
    one = np.asarray(at_motion, dtype=np.float64)
    probe = np.asarray(at_probe, dtype=np.float64)
    if probe.ndim == one.ndim:  # one part: the whole motion
        probe = probe[..., None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        powers = np.log(probe / one[..., None, :]) / np.log(POWER_PROBE)
    grows = np.isfinite(powers) & (powers >= 0.5)
    power = np.where(grows, powers, np.inf).min(-2, initial=np.inf)
    sized = (one > 0) & np.isfinite(one)
    moves = sized & grows.any(-2)
    largest = np.where(sized, one, -np.inf).max(-1, initial=-np.inf, keepdims=True)
    beside = np.where(np.isfinite(largest), ROUNDING * largest, np.nan)
    return np.where(moves, ROUNDING ** np.clip(np.nan_to_num(power), 1.0, 3.0) * one, beside)


def motion_sizes(
    columns_at: Callable[[np.ndarray], Sequence[np.ndarray]], parts: int = 1
) -> tuple[np.ndarray, np.ndarray]:
    """The sizes a regression's floors of the rounding rule are made of
    (:func:`rounding_floors`), of a regression that knows the motion its columns are made of:
    ``columns_at(scales)`` gives its columns at the log's typical motion with each of its
    ``parts`` scaled by each row of ``scales`` ``[S, parts]``, each column an array
    ``[S, ...]`` of its entries at each row, read at scale 1 (``[P]``) and with each part
    alone at :data:`POWER_PROBE` (``[parts, P]``); a column's size there is its typical size
    (:func:`column_sizes` of its entries). All the scales in one call, so that a regression
    evaluates its columns once for all of them (a Fossen regression's cost a model per unknown;
    read one scale a call, a floor read evaluated them seven times). One part: the whole
    motion; six: each velocity, for columns that are products of them (SINDy's library terms;
    a Fossen regression's, each velocity with its acceleration), so that a product of a
    velocity of rounding is rounding."""
    scales = np.vstack([np.ones(parts), np.where(np.eye(parts, dtype=bool), POWER_PROBE, 1.0)])
    columns = [np.reshape(c, (len(scales), -1)) for c in columns_at(scales)]
    out = np.zeros((len(scales), len(columns)))
    # columns of one length sized in one call (the loop's screen sizes hundreds of
    # candidates), each scale's entries a column of their own, drawn as each alone would be
    # (column_sizes draws by the count)
    for length in {c.shape[1] for c in columns}:
        same = [j for j, c in enumerate(columns) if c.shape[1] == length]
        # [length, S, J] stacked as such, one copy (a transpose of [S, length, J] was two)
        flat = np.stack([columns[j].T for j in same], 2).reshape(length, -1)
        out[:, same] = column_sizes(flat).reshape(len(scales), len(same))
    return out[0], out[1:]


def motion_floors(
    columns_at: Callable[[np.ndarray], Sequence[np.ndarray]], parts: int = 1
) -> np.ndarray:
    """Each column's floor of the rounding rule (:func:`rounding_floors`) of the sizes
    :func:`motion_sizes` reads of ``columns_at`` in ``parts`` parts of the motion."""
    return rounding_floors(*motion_sizes(columns_at, parts))


def library_floors(
    nu: np.ndarray, library: BasisLibrary, length: float, inputs: np.ndarray | None = None
) -> np.ndarray:
    """Each column's floor of the rounding rule (:func:`motion_floors`) of ``library`` (SINDy's
    and the named-mask synthesis's basis terms) evaluated on the velocities ``nu`` ``[N, 6]``,
    then of the ``inputs`` ``[N, n_u]`` appended to it (SINDy with control's τ): each term at
    the log's typical motion (:func:`kind_sizes` of ``nu``, angular rates over ``length``, as
    the Fossen regression's floors), and with each velocity alone times :data:`POWER_PROBE`, as
    a term is a product of them: q|q| of a real pitch rate 1e-6 of the yaw rate is data (power
    2), u·w of a log whose w is rounding is rounding (power 1 in w). An input does not grow
    with the motion: its floor is that of a column with no power (ROUNDING × the largest
    column at the typical motion)."""
    reference = kind_sizes(np.asarray(nu, dtype=np.float64), length)
    passed = [] if inputs is None else list(np.asarray(inputs, dtype=np.float64).T)

    def columns_at(scales: np.ndarray) -> list[np.ndarray]:
        held = [np.broadcast_to(x, (len(scales), x.size)) for x in passed]
        return [*library(scales * reference).T, *held]

    return motion_floors(columns_at, len(DOFS))


def rounding_columns(
    column_rms: np.ndarray, reference: float | np.ndarray, floors: np.ndarray | None = None
) -> np.ndarray:
    """Which columns of RMS ``column_rms`` ``[P]`` are rounding, not data (the rounding rule,
    :data:`ROUNDING`): those at most ROUNDING × ``reference`` (the typical size of a regressor
    of the regression, :func:`typical_size`, or one per column: :func:`kind_sizes`), or at
    most their own floor in ``floors`` where it is not NaN (:func:`rounding_floors`); a NaN RMS
    too, as nothing shows it above. A column of rounding is zero: scaled to unit RMS it would
    be a full-size column of noise. Leading axes (``[..., P]``, ``reference`` ``[...]``, one
    per regression, or ``[..., P]``, one per column): as many regressions."""
    raw = np.asarray(column_rms, dtype=np.float64)
    reference = np.asarray(reference, dtype=np.float64)
    if reference.ndim < raw.ndim:  # one per regression
        reference = reference[..., None]
    floor = np.broadcast_to(ROUNDING * reference, raw.shape)
    if floors is not None:  # a column's own floor, where its regression gives one
        own = np.asarray(floors, dtype=np.float64)
        floor = np.where(np.isnan(own), floor, own)
    return ~(raw > floor)


def excitation_report(
    phi: np.ndarray,
    names: list[str],
    groups: dict[str, list[str]] | None = None,
    tol: float = 1e-6,
) -> ExcitationReport:
    """Diagnose the regressor ``phi`` ``[N, P]`` whose columns belong to parameters ``names``."""
    phi = np.asarray(phi, dtype=np.float64)
    if phi.ndim != 2 or phi.shape[1] != len(names):
        raise ValueError("phi must be [N, len(names)]")
    reference = typical_size(phi)
    return excitation_from_gram(phi.T @ phi, phi.shape[0], names, groups, tol, reference=reference)


def excitation_from_gram(
    gram: np.ndarray,
    n: int,
    names: list[str],
    groups: dict[str, list[str]] | None = None,
    tol: float = 1e-6,
    left_out: Sequence[str] = (),
    column_rms: np.ndarray | None = None,
    reference: float = 0.0,
    floors: np.ndarray | None = None,
    by_equation: np.ndarray | None = None,
) -> ExcitationReport:
    """The same report from ΦᵀΦ (cheap for long logs): singular values of the unit-RMS-scaled
    regressor are the square roots of the eigenvalues of its scaled Gram matrix; an eigenvalue
    at or below the rounding of the largest is 0 (:func:`_resolved`): its singular value is 0,
    the condition number inf, and its direction collinear, whatever the BLAS kernels' last
    bits made of it. ``left_out``:
    parameters whose regressor the caller had only in rows it left out (not finite): their
    verdict says so, not "zero regressor".

    A column is zero (Weiss eq. 95's α₁ = 0) when its RMS is at most ``tol`` of the largest
    column of its DOF equation (of the whole regression without ``by_equation``), though
    never of more than ``reference`` (a millionth of the other regressors is not measured
    beside them), or at most :data:`ROUNDING` of ``reference``, the typical size of a
    regressor of the whole regression this one is a block of (:func:`typical_size`;
    McCarter's Ξ, eq. 4.20, solved force by force): a block of one column has no other to be
    compared with, and one of rounding (1e-17) fitted to a target of rounding read as a
    precise estimate. Without ``reference`` (0) the largest column RMS stands for it, which
    one column singular on a few rows would inflate.
    ``column_rms``: each column's RMS unweighted, where ``gram`` is weighted (weights that
    scale each equation by its residual made a column of rounding as large as any); the
    rounding rule reads it, and the tol rule without ``by_equation``. ``floors`` ``[P]``:
    each column's floor of the rounding rule where it is not NaN (:func:`rounding_floors`, a
    Fossen regression's), in place of ROUNDING × ``reference``: a column is compared with
    itself at the log's typical motion, to its power (a yaw rate 1e-6 of the surge speed is
    measured, and its r|r| 1e-12). The tol rule still holds beside it.
    ``by_equation`` ``[E, P]``: each column's unweighted RMS over the rows of each DOF
    equation the regression stacks (:func:`equation_rms`); the tol rule then compares a
    column with the columns of each equation it is in, and it is excited where one of them
    measures it: the r|r| of a yaw rate 1e-4 of the surge speed, 1e-8 of X:u|u| and called
    zero beside it in one regression, is measured by its N equation; a sway under a 1e-9-N
    force has v|v| 1e-11 of v̇'s column in the Y equation, zero beside it. None: the
    regression is one equation (``column_rms``)."""
    p = len(names)
    rms = _gram_rms(gram, n)
    raw = rms if column_rms is None else np.asarray(column_rms, dtype=np.float64)
    live = (rms > 0) & measured_columns(raw, reference, floors, by_equation, tol)
    unexcited = [names[j] for j in range(p) if not live[j]]
    normed = _unit_scaled(gram, rms, live, n)
    # the spectrum of the live columns only: a zero column's exact null direction is
    # degenerate with a collinear pair's, and eigh mixed the two, so that the pair was not
    # named (its values then kept the pseudo-inverse's, with a standard error)
    idx = np.flatnonzero(live)
    sv, weak, vec = _spectrum(normed[np.ix_(idx, idx)], p, tol)
    rank = int(np.sum(~weak))
    condition = float((sv[0] / sv[p - 1]) ** 2) if p and sv[p - 1] > 0 else float("inf")
    collinear: list[str] = []
    for k in range(idx.size):
        if weak[k]:
            collinear += [names[j] for j in idx[np.abs(vec[:, idx.size - 1 - k]) > 0.3]]
    collinear = sorted(set(collinear), key=names.index)
    group_min = {}
    for g, members in (groups or {}).items():
        cols = [names.index(m) for m in members]
        sub = _resolved(np.linalg.eigvalsh(normed[np.ix_(cols, cols)]))
        group_min[g] = float(np.sqrt(sub.min())) if sub.size else 0.0
    warnings = _verdict_warnings(unexcited, collinear, rank, p, left_out)
    unread = [n for n in unexcited if n in left_out]
    return ExcitationReport(
        n,
        p,
        rank,
        condition,
        [float(x) for x in sv],
        group_min,
        unexcited,
        collinear,
        warnings,
        unread,
    )


def measured_columns(
    column_rms: np.ndarray,
    reference: float | np.ndarray = 0.0,
    floors: np.ndarray | None = None,
    by_equation: np.ndarray | None = None,
    tol: float = 1e-6,
) -> np.ndarray:
    """Which columns ``[P]`` of a regression its data measure, by the two rules of
    :func:`excitation_from_gram` (which says the rest "not excited (zero regressor)"): above
    ``tol`` of the largest column of a DOF equation they are in (``by_equation`` ``[E, P]``,
    each column's unweighted RMS in each equation; None: one equation, ``column_rms``), that
    largest capped at ``reference``; and above their floor of the rounding rule
    (:func:`rounding_columns`: ``floors`` where not NaN, else :data:`ROUNDING` ×
    ``reference``). ``reference``: the typical size of a regressor of the whole regression
    (:func:`typical_size`); 0: the largest ``column_rms`` stands for it. Leading axes
    (``column_rms`` and ``floors`` ``[..., P]``, ``reference`` ``[...]``, ``by_equation``
    ``[..., E, P]``): as many regressions, judged each on its own (a candidate column beside
    a fit's, for each candidate)."""
    raw = np.asarray(column_rms, dtype=np.float64)
    reference = np.asarray(reference, dtype=np.float64)
    # the largest RMS only where no robust reference is given (from ΦᵀΦ alone): one column
    # singular on a few rows would set it
    typical = np.where(reference > 0, reference, raw.max(-1, initial=0.0))
    # the tol rule is no limit of the scaled Gram (columns are scaled to unit RMS, so one a
    # millionth of another is not lost in it), but a verdict on the equation's other columns:
    # its size is their largest, capped at the typical one, as one column singular on a few
    # rows (an (η − 1) term at U = 0, 1e12) made every other column of its block "zero
    # regressor"; unweighted, as weights of 1/σ̂² per equation (beside one of exact data:
    # 1e16) did the same. Within each equation, as each is fitted against its own target,
    # in its own units (N, N m): X's u|u| said nothing of N's rows, yet called N:r|r| zero
    sizes = raw[..., None, :] if by_equation is None else np.asarray(by_equation, np.float64)
    block = np.minimum(sizes.max(-1, initial=0.0), typical[..., None])
    # a column in several equations' rows (an added mass: its ν̇ in its own equation, its
    # C_A(ν)ν in others) is measured where any one of them measures it beside that
    # equation's columns: its rows there are data whatever it is in the other equations
    measured = (sizes > tol * block[..., None]).any(-2)
    return measured & ~rounding_columns(raw, typical, floors)


def _resolved(eig: np.ndarray) -> np.ndarray:
    """The eigenvalues ``eig`` of a symmetric positive semi-definite matrix, those at or below
    the rounding of the largest (size × eps × largest, :func:`numpy.linalg.matrix_rank`'s
    tolerance) set to 0. The eigen-solver computes each to within about that of the largest,
    so below it a value is rounding, not a measurement: an exact null direction (a thrust and
    a bias both constant) came out +2e-16 of the largest with one CPU's BLAS kernels and
    -2e-16 with another's, a condition number of 1.4e16 on one and inf on the other."""
    eig = np.asarray(eig, dtype=np.float64)
    top = eig.max(-1, initial=0.0, keepdims=True)  # a stack ``[..., m]``: each its own largest
    return np.where(eig > eig.shape[-1] * np.finfo(np.float64).eps * top, eig, 0.0)


def _gram_rms(gram: np.ndarray, n: int) -> np.ndarray:
    """Each column's RMS over ``n`` rows from its Gram matrix ``[..., m, m]``: ``[..., m]``."""
    return np.sqrt(np.clip(np.diagonal(gram, axis1=-2, axis2=-1), 0.0, None) / max(n, 1))


def _unit_scaled(gram: np.ndarray, rms: np.ndarray, live: np.ndarray, n: int) -> np.ndarray:
    """The Gram matrix ``[..., m, m]`` of the regressor scaled to unit-RMS columns over ``n``
    rows (``rms`` :func:`_gram_rms`), its columns not ``live`` zeroed."""
    d = np.where(live, 1.0 / np.where(live, rms, 1.0), 0.0)
    return gram * (d[..., :, None] * d[..., None, :]) / max(n, 1)


def _spectrum(
    normed: np.ndarray, p: int, tol: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The singular values ``[..., p]`` of a regressor scaled to unit-RMS columns whose
    scaled Gram matrix over its ``m`` live columns is ``normed`` ``[..., m, m]`` (the other
    ``p - m`` are 0), largest first; which of them the rank does not count (at most √``tol``
    of the largest); and the eigenvectors of ``normed`` (None where m = 0). A stack is
    decomposed in one call, each matrix as it alone would be (:func:`gram_ranks`)."""
    m = normed.shape[-1]
    eig, vec = np.linalg.eigh(normed) if m else (np.zeros(normed.shape[:-1]), None)
    zeros = np.zeros((*eig.shape[:-1], p - m))
    sv = np.concatenate([np.sqrt(_resolved(eig)[..., ::-1]), zeros], -1)
    # one threshold for both verdicts: a direction rank does not count is named collinear
    weak = sv <= np.sqrt(tol) * (sv[..., :1] if p else 1.0)
    return sv, weak, vec


def gram_ranks(grams: np.ndarray, n: int, tol: float = 1e-6) -> np.ndarray:
    """The rank :func:`excitation_from_gram` finds in each of a stack of Gram matrices
    ``grams`` ``[K, m, m]`` of ``n`` rows ``[K]``, where every column passes its size rules
    (unit ``column_rms``, ``reference`` 1: only a zero column is left out). The matrices with
    the same columns left out are decomposed in one call: a call of excitation_from_gram a
    matrix (the loop's screen judges hundreds of candidates' augmented regressions a pass)
    took the demo's loop 0.16 s, three times what the stack takes."""
    grams = np.asarray(grams, dtype=np.float64)
    k, m = grams.shape[0], grams.shape[-1]
    ranks = np.zeros(k, dtype=int)
    if not (k and m):
        return ranks
    rms = _gram_rms(grams, n)  # excitation_from_gram's scaling, each matrix as alone
    live = rms > 0
    normed = _unit_scaled(grams, rms, live, n)
    patterns, which = np.unique(live, axis=0, return_inverse=True)
    for j, pattern in enumerate(patterns):
        members = np.flatnonzero(which.reshape(-1) == j)
        idx = np.flatnonzero(pattern)
        _, weak, _ = _spectrum(normed[np.ix_(members, idx, idx)], m, tol)
        ranks[members] = np.sum(~weak, -1)
    return ranks


def _verdict_warnings(
    unexcited: list[str],
    collinear: list[str],
    rank: int,
    p: int,
    left_out: Sequence[str] = (),
    remembered: Sequence[str] = (),
) -> list[str]:
    """The report's warnings: the parameters it names, or its rank deficit when it names none;
    an unexcited one in ``left_out`` had its regressor only in rows left out (not finite), one
    in ``remembered`` keeps a value learnt before a recursive estimator's memory
    (:data:`REMEMBERED`, whichever of the two the memory lacked: its value rests on data)."""
    warnings = []
    kept = [n for n in unexcited if n in remembered]
    zero = [n for n in unexcited if n not in left_out and n not in remembered]
    unread = [n for n in unexcited if n in left_out and n not in remembered]
    if kept:
        warnings.append(f"{REMEMBERED}: {', '.join(kept)}")
    if zero:
        warnings.append(f"not excited by this data (zero regressor): {', '.join(zero)}")
    if unread:
        warnings.append(
            "not measured (every row that reads them was left out: its target or regressor is "
            f"not finite): {', '.join(unread)}"
        )
    if collinear:
        warnings.append(
            f"not separable from each other (collinear regressors): {', '.join(collinear)}"
        )
    if rank < p and not warnings:
        warnings.append(f"the regressor has rank {rank} < {p} parameters")
    return warnings


def changed_verdicts(before: ExcitationReport, after: ExcitationReport) -> list[str]:
    """What the excitation check ``after``, of the same regression refitted with other row
    weights (feasible weighting's second pass, Weiss eqs 93-98), says that ``before`` did
    not: the parameters it newly finds unexcited or collinear (or its rank deficit, where it
    names none and its rank fell), and those ``before`` named that it excites and separates.
    Empty for the same verdict: ``before``'s warnings were given, and are not to be repeated.
    The weights change which equations dominate the Gram matrix, so a pair separable only in
    an equation that 1/σ̂² scales down beside one of exact data is collinear after them."""
    unexcited = [n for n in after.unexcited if n not in before.unexcited]
    collinear = [n for n in after.collinear if n not in before.collinear]
    # the rank line only where no name says it, as in the report's own warnings
    rank = after.rank if after.rank < before.rank else after.n_params
    lines = _verdict_warnings(unexcited, collinear, rank, after.n_params, after.not_measured)
    flagged = {*after.unexcited, *after.collinear}
    cleared = [n for n in [*before.unexcited, *before.collinear] if n not in flagged]
    if cleared:
        lines.append(
            f"excited and separable after all: {', '.join(dict.fromkeys(cleared))} (the "
            "estimate gives their values and standard errors)"
        )
    return lines


def combined_excitation(
    parts: Sequence[tuple[Sequence[str], ExcitationReport | None]], names: Sequence[str]
) -> ExcitationReport | None:
    """One report for an estimate of ``names`` assembled from parts, each (the parameters it
    gives the estimate, its report under those names or None where it made no check): a
    decoupled sequence's steps (Weiss eqs 99-108), Caccia's two steps. A parameter takes the
    verdict of the last part that gives it (a later step's refit replaces an earlier value,
    and its verdict with it); None when no part that gives one had a report.

    No regressor of the whole estimate exists, so nothing here claims one was measured:
    ``rank`` counts the parameters a part's check found excited and separable (one of a part
    without a check, or of no part, counts as not, and a warning names it), so ``persistent``
    holds only when every parameter was checked and passed; ``condition`` is the worst (largest) of
    the parts' own; ``singular_values`` and ``group_min_singular`` are left empty (each part's
    are of its own unit-scaled regressor, not parts of one spectrum); ``n_samples`` sums the
    parts' rows."""
    last: dict[str, int] = {}
    for k, (given, _) in enumerate(parts):
        last.update(dict.fromkeys((n for n in given if n in names), k))
    used = sorted(set(last.values()))
    reports = {k: parts[k][1] for k in used if parts[k][1] is not None}
    if not reports:
        return None
    unchecked = [n for n in names if n in last and last[n] not in reports]
    unexcited = [n for n in names if last.get(n) in reports and n in reports[last[n]].unexcited]
    collinear = [n for n in names if last.get(n) in reports and n in reports[last[n]].collinear]
    unread = [n for n in unexcited if n in reports[last[n]].not_measured]
    kept = [n for n in unexcited if n in reports[last[n]].remembered]
    unchecked += [n for n in names if n not in last]
    rank = len(names) - len({*unexcited, *collinear, *unchecked})
    # no rank-deficit line: there is no one regressor whose rank fell short
    warnings = _verdict_warnings(unexcited, collinear, len(names), len(names), unread, kept)
    if unchecked:
        warnings.append(
            f"not checked for excitation (a part without a check): {', '.join(unchecked)}"
        )
    conditions = [r.condition for r in reports.values()]
    return ExcitationReport(
        sum(r.n_samples for r in reports.values()),
        len(names),
        rank,
        max(conditions) if not any(math.isnan(c) for c in conditions) else math.nan,
        [],
        {},
        unexcited,
        collinear,
        warnings,
        unread,
        kept,
    )
