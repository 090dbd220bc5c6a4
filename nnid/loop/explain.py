"""What a hybrid's network learned, in the vocabulary of physical effects.

A hybrid's learned force f_θ (:meth:`nnid.models.hybrid.HybridModel.correction`, evaluated at
the measured states and inputs of a log) is what its physics misses. Every candidate effect of
the residual loop (:func:`nnid.loop.effects.candidates`: linear, quadratic and coupled damping
over McCarter's basis library, installation coefficients, buoyancy and restoring offsets,
constant forces, added mass, and, linearised at zero, current, actuator lag and deadband) has a
column: how the Fossen equation error R changes per unit of it (the regression columns the loop
screens). The physics' own fitted parameters get a column too, so that a network that merely
re-estimates a fitted coefficient is named as doing that. If the network learned effect k of
size δ, then f_θ ≈ −col_k δ; pysindy's STLSQ over all columns at once (scaled to unit norm, per
DOF weighted by the RMS input force, with the loop's small ridge against near-copies of one
column) keeps the few that explain it, and each kept term is ranked by the share of the learned
force it explains (Pratt's measure: the shares add up to what the terms explain together).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from nnid.loop.diagnose import Workspace, damping_block, sensitivity
from nnid.loop.effects import Candidate, candidates
from nnid.models.parametric import vehicle_with
from nnid.physics.dofs import DOFS
from nnid.trainers.sindy import compress


@dataclass
class Term:
    """One term of the learned force: an effect of the vocabulary (or a fitted parameter of
    the physics, ``kind`` "fitted"), its size in the vocabulary's units, and the share of the
    learned force's weighted sum of squares it explains (the terms' shares add up to
    :attr:`Explanation.explained`; below zero: it cancels part of a correlated term)."""

    name: str
    kind: str
    meaning: str
    value: float
    share: float

    def as_dict(self) -> dict:
        return {
            "effect": self.name,
            "kind": self.kind,
            "meaning": self.meaning,
            "value": self.value,
            "share": self.share,
        }


@dataclass
class Explanation:
    """The ranked terms, how much of the learned force they explain together (R²), and the
    learned force's RMS per DOF (N, N m)."""

    terms: list[Term]
    explained: float
    force_rms: dict[str, float]
    samples: int
    candidates: int
    notes: list[str] = field(default_factory=list)

    def top(self, n: int = 3) -> list[str]:
        return [t.name for t in self.terms[:n]]

    def as_dict(self) -> dict:
        return {
            "terms": [t.as_dict() for t in self.terms],
            "explained": self.explained,
            "force_rms": self.force_rms,
            "samples": self.samples,
            "candidates": self.candidates,
            "notes": self.notes,
        }


def _fitted(name: str) -> Candidate:
    """A parameter of the physics fit as a candidate column (its value is the change)."""
    return Candidate(name, "fitted", name, dofs=DOFS)


def explain(
    model,
    log: pd.DataFrame,
    share: float = 0.02,
    ridge: float = 0.1,
    max_samples: int = 3000,
    coupled: bool = True,
) -> Explanation:
    """Name the dominant terms of a fitted hybrid's learned force on ``log`` (module
    docstring). ``share``: a term must explain this fraction of the learned force on its own
    to be kept; ``max_samples``: evenly spaced samples of the log used (the columns are
    [samples × 6, ~850])."""
    force = model.correction(log)
    if len(log) > max_samples:
        keep = np.unique(np.linspace(0, len(log) - 1, max_samples).round().astype(int))
        log, force = log.iloc[keep], force.iloc[keep]
    log, _ = model._data(log, accelerations=True)
    parts = model.joint_parts()
    fitted_names = list(model.structure_.names)
    vehicle = vehicle_with(model.vehicle, {n: parts.get(n) for n in fitted_names})
    ws = Workspace(log, log.iloc[:0], vehicle, filter_lambda=None, zoh_midpoint=False)
    data = ws.arrays(vehicle)
    dofs = [d for d in model.dofs_]
    pool = [c for c in candidates(vehicle, log, coupled) if set(c.dofs) & set(dofs)]
    taken = {c.parameter for c in pool if c.linear}
    pool += [_fitted(n) for n in fitted_names if n not in taken]
    blocks: list[np.ndarray] = []
    order: list[Candidate] = []
    notes: list[str] = []
    damping = [c for c in pool if c.linear and ":" in c.parameter]
    other = [c for c in pool if c.linear and ":" not in c.parameter]
    for start in range(0, len(damping), 64):
        chunk = damping[start : start + 64]
        blocks.append(damping_block(ws, vehicle, chunk, data))
        order += chunk
    for cand in other:  # one at a time: some pairs cannot share a regression (W and r_b)
        blocks.append(ws.columns(vehicle, [cand.parameter], "train"))
        order.append(cand)
    for cand in (c for c in pool if not c.linear):
        lo, hi = cand.bounds  # type: ignore[misc]
        v0 = cand.current_value(vehicle)
        h = 1e-3 * (hi - lo)
        try:
            blocks.append(sensitivity(ws, vehicle, cand, v0, v0 + h)[0])
            order.append(cand)
        except ValueError as exc:  # an effect this vehicle cannot take
            notes.append(f"{cand.name}: {exc}")
    cols = np.concatenate(blocks, 2)  # [N, 6, K]
    rows = [DOFS.index(d) for d in dofs]
    w = 1.0 / np.asarray(model.input_scale_)[rows]
    y = -force.to_numpy(np.float64)[:, rows] * w
    x = cols[:, rows, :] * w[None, :, None]
    n = y.shape[0]
    x = x.reshape(n * len(rows), -1)
    y = y.reshape(-1)
    ok = np.isfinite(x).all(1) & np.isfinite(y)
    x, y = x[ok], y[ok]
    norms = np.linalg.norm(x, axis=0)
    usable = norms > 1e-12 * max(float(norms.max()), 1e-300)
    x = x[:, usable] / norms[usable]
    order = [c for c, u in zip(order, usable, strict=True) if u]
    total = float(y @ y)
    if total == 0.0 or not order:
        return Explanation([], 0.0, _rms(force, dofs), n, len(order), notes)
    coef = _stlsq(x, y, np.sqrt(share * total), ridge)
    fitted = x @ coef
    terms = []
    for k in np.flatnonzero(coef):
        cand = order[k]
        delta = float(coef[k] / norms[usable][k])
        # Pratt's measure: coefficient times the term's projection on the force; the parts
        # add up to the explained share even where the columns are correlated (coef² alone
        # added to half of it), and a term that cancels part of another comes out negative
        part = float(coef[k] * (x[:, k] @ y) / total)
        if cand.kind == "fitted":
            value, meaning = parts.get(cand.name) + delta, f"refits {cand.name} of the physics"
        else:
            value, meaning = cand.value(delta, vehicle), cand.meaning
        terms.append(Term(cand.name, cand.kind, meaning, value, part))
    terms.sort(key=lambda t: -t.share)
    explained = 1.0 - float(np.sum((y - fitted) ** 2)) / total
    return Explanation(terms, explained, _rms(force, dofs), n, len(order), notes)


def _stlsq(x: np.ndarray, y: np.ndarray, threshold: float, ridge: float) -> np.ndarray:
    """pysindy's STLSQ on the compressed regression (unit-norm columns): the coefficients (a
    kept term explains at least ``threshold²`` of ‖y‖² on its own)."""
    import pysindy as ps

    r, b, _ = compress(x, y[:, None])
    # the compressed system has the minimiser of the full one: the same threshold applies
    opt = ps.STLSQ(threshold=threshold, alpha=ridge / y.size, max_iter=20)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*eliminated all coefficients.*")
        opt.fit(r, b)
    return np.ravel(opt.coef_)


def _rms(force: pd.DataFrame, dofs: list[str]) -> dict[str, float]:
    return {d: float(np.sqrt(np.mean(force.iloc[:, DOFS.index(d)].to_numpy() ** 2))) for d in dofs}
