"""Viscous damping as a linear combination of basis terms (McCarter eq. 3.12).

τ_D(ν) = Θ ξ(ν) is the hydrodynamic force on the vehicle; Fossen's D(ν)ν = −τ_D(ν). Weiss's
quadratic model (eq. 45) and Fossen's linear + quadratic model (McCarter 3.41) are masks of
the same structure; any term of the basis library can be added.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import torch
from torch import Tensor

from nnid.physics.damping_library import (
    LIBRARY,
    canonical_term,
    evaluate_terms,
    mask_terms,
    term_codes,
)
from nnid.physics.dofs import FORCES


def parse_coefficient_key(key: str) -> tuple[str, str]:
    """'X:u*abs(u)' -> ('X', 'u*abs(u)') with the term in its canonical spelling."""
    force, sep, term = key.partition(":")
    if not sep or force not in FORCES:
        raise ValueError(
            f"damping coefficient '{key}': expected '<F>:<term>' with F in X Y Z K M N, "
            "e.g. 'X:u*abs(u)'"
        )
    return force, canonical_term(term)


class DampingTerms:
    """The damping structure: basis terms, and a 6 x K coefficient matrix (force = Θ ξ(ν)).

    ``mask`` marks which (force, term) entries belong to the model structure; entries outside it
    are zero. ``coefficients`` may be a tensor that requires grad.
    """

    def __init__(
        self,
        terms: tuple[str, ...],
        coefficients: Tensor,
        mask: Tensor | None = None,
        u_c: float = 0.0,
    ) -> None:
        self.terms = tuple(terms)
        self.coefficients = coefficients
        self.mask = (coefficients != 0) if mask is None else mask
        self.u_c = float(u_c)
        self.codes = term_codes(self.terms)

    @classmethod
    def from_spec(
        cls,
        model: str | None,
        coefficients: Mapping[str, float],
        u_c: float = 0.0,
        dtype=torch.float64,
    ) -> DampingTerms:
        """Build from a named mask and known coefficients ``{"X:u*abs(u)": -61.1, ...}``.

        The structure is the mask's terms plus every declared coefficient; undeclared
        coefficients of the mask are zero (unknown, to be identified).
        """
        entries: set[tuple[str, str]] = set()
        if model:
            for force, terms in mask_terms(model).items():
                entries.update((force, t) for t in terms)
        values = {}
        for key, value in coefficients.items():
            force, term = parse_coefficient_key(key)
            entries.add((force, term))
            values[(force, term)] = float(value)
        terms = tuple(dict.fromkeys(t for _, t in sorted(entries, key=_entry_order)))
        coef = torch.zeros(6, len(terms), dtype=dtype)
        mask = torch.zeros(6, len(terms), dtype=torch.bool)
        for force, term in entries:
            i, j = FORCES.index(force), terms.index(term)
            mask[i, j] = True
            coef[i, j] = values.get((force, term), 0.0)
        return cls(terms, coef, mask, u_c)

    def basis(self, nu: Tensor) -> Tensor:
        """ξ(ν) ``[..., K]``."""
        return evaluate_terms(nu, self.codes, self.u_c)

    def force(self, nu: Tensor) -> Tensor:
        """τ_D(ν) = Θ ξ(ν), the damping force on the vehicle ``[..., 6]``."""
        if not self.terms:
            return torch.zeros_like(nu)
        return self.basis(nu) @ self.coefficients.transpose(-1, -2)

    def as_dict(self) -> dict[str, float]:
        """Coefficients inside the structure, keyed '<F>:<term>'."""
        coef = self.coefficients.detach().cpu().numpy()
        mask = self.mask.cpu().numpy()
        return {
            f"{FORCES[i]}:{t}": float(coef[i, j])
            for i in range(6)
            for j, t in enumerate(self.terms)
            if mask[i, j]
        }

    def numpy(self) -> tuple[np.ndarray, np.ndarray]:
        """(coefficient matrix, atom codes) as arrays for compiled kernels."""
        return self.coefficients.detach().cpu().numpy().astype(np.float64), self.codes


def _entry_order(entry: tuple[str, str]) -> tuple[int, str]:
    _, term = entry
    return (LIBRARY.index(term) if term in LIBRARY else len(LIBRARY), term)
