"""The hydrodynamic basis library: McCarter's 132 viscous basis functions (Appendix C).

A basis term is written in code form, e.g. ``u*abs(v)``, ``abs(q)*Vw`` or ``u*v*(eta-1)``: a
product of factors drawn from the atoms ``u v w p q r``, ``abs(u)`` … ``abs(r)``, ``U``, ``V``,
``Vv``, ``Vw`` and ``(eta-1)`` where (McCarter eqs C.8-C.12)

    U = sqrt(u² + v² + w²),  V = sqrt(v² + w²),  Vv = V sign(v),  Vw = V sign(w),  η = u_c / U.

sign(x) is 0 for |x| ≤ :data:`SIGN_FLOOR` (:func:`rounded_sign`): a v or w that is only rounding
must not switch a full-size V on with a random sign.

Every term is encoded as up to three atom indices, so one gather-and-product evaluates any set
of terms on NumPy arrays, PyTorch tensors, or inside the compiled simulator kernel.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from functools import lru_cache

import numpy as np
import torch

from nnid.physics.dofs import DOFS

ATOMS = (
    *DOFS,
    *(f"abs({s})" for s in DOFS),
    "U",
    "V",
    "Vv",
    "Vw",
    "(eta-1)",
    "1",
)
ATOM_INDEX = {name: i for i, name in enumerate(ATOMS)}
ONE = ATOM_INDEX["1"]
MAX_FACTORS = 3
# Keeps sqrt differentiable at rest and η finite; far below any speed a log resolves.
_TINY = 1e-30
#: m/s: a v or w at most this is rounding, its sign 0 in Vv and Vw. Float64 arithmetic on
#: vehicle speeds (0.01-10 m/s) leaves residues of 1e-18-1e-15 m/s (a vehicle that never
#: heaves logs w ~ 1e-17), integration a few orders more; no velocity sensor resolves below
#: ~1e-6 m/s. Absolute, not relative to the data's largest w: a term's value at a sample must
#: not depend on the other samples evaluated with it (the compiled kernel sees one at a time).
SIGN_FLOOR = 1e-9


def _library_names() -> tuple[str, ...]:
    s = DOFS
    names = list(s)  # C.1
    names += [f"abs({a})" for a in s]  # C.2
    pairs = [f"{s[i]}*{s[j]}" for i in range(6) for j in range(i, 6)]
    names += pairs  # C.3
    names += [f"{a}*abs({b})" for a in s for b in s]  # C.4
    for atom in ("V", "Vv", "Vw"):  # C.5
        names += [f"{a}*{atom}" for a in s]
        names += [f"abs({a})*{atom}" for a in s]
    names += [f"{p}*(eta-1)" for p in pairs]  # C.6
    names += [f"{a}*V*(eta-1)" for a in s]
    return tuple(names)


LIBRARY: tuple[str, ...] = _library_names()
"""The 132 terms of McCarter eq. C.7, in his order."""

_FACTOR = re.compile(r"abs\([uvwpqr]\)|\(eta-1\)|Vv|Vw|[uvwpqrUV]")


@lru_cache(maxsize=4096)
def parse_term(term: str) -> tuple[int, ...]:
    """Atom indices of a term, sorted, padded with the unit atom to three factors.

    Raises ValueError naming the term when it is not a product of known atoms.
    """
    text = term.replace(" ", "")
    parts = text.split("*") if text else []
    atoms = []
    for part in parts:
        if not _FACTOR.fullmatch(part):
            raise ValueError(
                f"basis term '{term}': '{part}' is not a factor; factors are u v w p q r, "
                "abs(u)..abs(r), U, V, Vv, Vw and (eta-1), joined by '*'"
            )
        atoms.append(ATOM_INDEX[part])
    if not atoms or len(atoms) > MAX_FACTORS:
        raise ValueError(f"basis term '{term}' must have 1 to {MAX_FACTORS} factors")
    return tuple(sorted(atoms)) + (ONE,) * (MAX_FACTORS - len(atoms))


@lru_cache(maxsize=1)
def _canonical_by_code() -> dict[tuple[int, ...], str]:
    return {parse_term(name): name for name in LIBRARY}


def canonical_term(term: str) -> str:
    """The library spelling of a term (``abs(v)*u`` -> ``u*abs(v)``); other valid terms as given."""
    code = parse_term(term)
    return _canonical_by_code().get(code, term.replace(" ", ""))


def term_codes(terms: Sequence[str]) -> np.ndarray:
    """``[len(terms), 3]`` int64 atom indices, for :func:`evaluate_terms` and compiled kernels."""
    return np.array([parse_term(t) for t in terms], dtype=np.int64).reshape(-1, MAX_FACTORS)


def rounded_sign(x: np.ndarray | torch.Tensor) -> np.ndarray | torch.Tensor:
    """sign(x) of an array or tensor, 0 where ``|x| <= SIGN_FLOOR`` (NaN stays NaN)."""
    sign = x.sign() if isinstance(x, torch.Tensor) else np.sign(x)
    return (abs(x) > SIGN_FLOOR) * sign


def atoms(nu, u_c: float = 0.0):
    """The atom values ``[..., 18]`` for body velocities ``nu`` ``[..., 6]`` (NumPy or torch)."""
    if isinstance(nu, torch.Tensor):
        xp, stack = torch, (lambda xs: torch.stack(xs, -1))
    else:
        nu = np.asarray(nu, dtype=np.float64)
        xp, stack = np, (lambda xs: np.stack(xs, -1))
    u, v, w = nu[..., 0], nu[..., 1], nu[..., 2]
    vel = [nu[..., i] for i in range(6)]
    big_v = xp.sqrt(v * v + w * w + _TINY)
    big_u = xp.sqrt(u * u + v * v + w * w + _TINY)
    eta_m1 = u_c / big_u - 1.0
    one = xp.ones_like(u)
    return stack(
        [
            *vel,
            *(xp.abs(x) for x in vel),
            big_u,
            big_v,
            big_v * rounded_sign(v),
            big_v * rounded_sign(w),
            eta_m1,
            one,
        ]
    )


def evaluate_terms(nu, codes, u_c: float = 0.0):
    """Basis terms ``[..., K]`` at ``nu`` ``[..., 6]`` for encoded ``codes`` ``[K, 3]``."""
    a = atoms(nu, u_c)
    if isinstance(a, torch.Tensor):
        idx = torch.as_tensor(np.asarray(codes), dtype=torch.long, device=a.device)
        return a[..., idx].prod(-1)
    codes = np.asarray(codes)
    if a.size // len(ATOMS) < _COLUMNWISE_MIN_SAMPLES:
        return a[..., codes].prod(-1)
    return _evaluate_columnwise(a, codes)


# Above this many samples the terms are built one column at a time (no [N, K, 3] gather).
_COLUMNWISE_MIN_SAMPLES = 4096


def _evaluate_columnwise(a: np.ndarray, codes: np.ndarray) -> np.ndarray:
    """Terms ``[..., K]`` from atoms ``[..., 18]``: each column is the product of its (at most
    three) atom rows, written in place into a column-major result; unit factors are skipped."""
    lead = a.shape[:-1]
    at = np.ascontiguousarray(a.reshape(-1, a.shape[-1]).T)  # [18, N], rows contiguous
    out = np.empty((codes.shape[0], at.shape[1]))
    for k, (i, j, m) in enumerate(codes):
        if j == ONE:
            out[k] = at[i]
            continue
        np.multiply(at[i], at[j], out=out[k])
        if m != ONE:
            out[k] *= at[m]
    return out.T.reshape(*lead, codes.shape[0])


class BasisLibrary:
    """A set of basis terms that evaluates vectorised on arrays and tensors.

    ``BasisLibrary()`` is McCarter's full 132-term library; pass ``terms`` for a subset.
    """

    def __init__(self, terms: Iterable[str] | None = None, u_c: float = 0.0) -> None:
        self.terms = tuple(canonical_term(t) for t in (LIBRARY if terms is None else terms))
        if len(set(self.terms)) != len(self.terms):
            raise ValueError("basis library terms must be unique")
        self.u_c = float(u_c)
        self.codes = term_codes(self.terms)

    def __len__(self) -> int:
        return len(self.terms)

    def __call__(self, nu):
        """Evaluate every term: ``[..., 6]`` -> ``[..., len(self)]``."""
        return evaluate_terms(nu, self.codes, self.u_c)

    def index(self, term: str) -> int:
        return self.terms.index(canonical_term(term))


def mask_terms(name: str) -> dict[str, tuple[str, ...]]:
    """The terms of a named model per force ``X Y Z K M N`` (McCarter App. D; Weiss eq. 45)."""
    from nnid.physics.damping_masks import MASKS

    if name not in MASKS:
        raise ValueError(f"unknown damping model '{name}'; expected one of {sorted(MASKS)}")
    return {force: tuple(canonical_term(t) for t in terms) for force, terms in MASKS[name].items()}
