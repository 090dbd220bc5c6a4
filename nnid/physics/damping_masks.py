"""Named viscous-damping model structures ("masks") over McCarter's 132-term basis.

Source: B. R. McCarter, *Experimental Evaluation of Viscous Hydrodynamic Force Models for
Autonomous Underwater Vehicles*, M.S. thesis, Virginia Tech, 2014: chapter 3 (sec. 3.2.1-3.2.8,
eqs 3.13-3.44) and Appendix D (Tables D.1-D.9, the model equations), cross-checked term by term
against the fitted coefficients of Appendix E (Tables E.1-E.11). The masked least-squares
synthesis that uses these masks is McCarter eqs 4.15-4.21.

``MASKS[model][force]`` is the tuple of canonical basis-term names (McCarter Appendix C, eqs
C.1-C.7, spelled as in ``nnid.physics.damping_library.LIBRARY``) that appear in the equation of
that force ``X Y Z K M N``. Terms are listed in the order of the basis vector C.7, not in the
order McCarter prints them. Each named model gives force = sum(coefficient * term) per axis.

``MASK_TERM_COUNTS[model]`` is the model complexity n-bar that McCarter reports (Tables 5.1 and
5.2, "n" column). Every mask's total length equals it; see the notes on ``uncoupled`` and
``coe`` for where the thesis is not self-consistent. ``weiss_quadratic`` is not McCarter's: it
is Weiss eq. 45 (diagonal quadratic drag), 6 terms by construction.
"""

from __future__ import annotations

from nnid.physics.dofs import DOFS, FORCES

# The 36 sign-preserving quadratics a*abs(b) of basis block C.4, in C.4 order.
_SIGN_PRESERVING = tuple(f"{a}*abs({b})" for a in DOFS for b in DOFS)

# fmt: off
MASKS: dict[str, dict[str, tuple[str, ...]]] = {
    # Gertler & Hagen (McCarter sec. 3.2.1, eqs 3.13-3.18; Appendix D Table D.4; coefficients Table
    # E.6). PDF garbling resolved: "Y_{|p|p}|p|", "M_{|q|q}|q|", "K_{|p|p}|p|", "N_{|r|r}|r|" are
    # p*abs(p), q*abs(q), p*abs(p), r*abs(r) (Table E.6 lists Y_{p|p|}, M_{q|q|}, K_{p|p|},
    # N_{r|r|}); D.4 prints "v^2 eta - 1" for v^2 (eta - 1) (eq. 3.13). Per force 10/16/16/13/17/16
    # = 88 = Table 5.1 n.
    "gertler_hagen": {
        "X": ("u*u", "v*v", "v*r", "w*w", "w*q", "p*r", "q*q", "r*r", "v*v*(eta-1)", "w*w*(eta-1)"),
        "Y": (
            "u*u", "u*v", "u*p", "u*r", "v*w", "v*q", "w*p", "w*r", "p*q", "q*r", "p*abs(p)", "v*V",
            "abs(r)*Vv", "u*v*(eta-1)", "u*r*(eta-1)", "v*V*(eta-1)",
        ),
        "Z": (
            "u*u", "u*w", "u*q", "v*v", "v*p", "v*r", "p*p", "p*r", "r*r", "u*abs(w)", "w*V",
            "abs(w)*V", "abs(q)*Vw", "u*w*(eta-1)", "u*q*(eta-1)", "w*V*(eta-1)",
        ),
        "K": (
            "u*u", "u*v", "u*p", "u*r", "v*w", "v*q", "w*p", "w*r", "p*q", "q*r", "p*abs(p)", "v*V",
            "u*u*(eta-1)",
        ),
        "M": (
            "u*u", "u*w", "u*q", "v*v", "v*p", "v*r", "p*p", "p*r", "r*r", "u*abs(w)", "q*abs(q)",
            "w*V", "q*V", "abs(w)*V", "u*w*(eta-1)", "u*q*(eta-1)", "w*V*(eta-1)",
        ),
        "N": (
            "u*u", "u*v", "u*p", "u*r", "v*w", "v*q", "w*p", "w*r", "p*q", "q*r", "r*abs(r)", "v*V",
            "r*V", "u*v*(eta-1)", "u*r*(eta-1)", "v*V*(eta-1)",
        ),
    },
    # Prestero (McCarter sec. 3.2.2, eqs 3.20-3.25; Appendix D Table D.7; coefficients Table E.9).
    # Garbled "X_{u|u}|u|" etc. read as u*abs(u) (sign-preserving quadratic); "wq" is w*q. Per force
    # 5/6/6/1/6/6 = 30 = Table 5.1 n.
    "prestero": {
        "X": ("v*r", "w*q", "q*q", "r*r", "u*abs(u)"),
        "Y": ("u*v", "u*r", "w*p", "p*q", "v*abs(v)", "r*abs(r)"),
        "Z": ("u*w", "u*q", "v*p", "p*r", "w*abs(w)", "q*abs(q)"),
        "K": ("p*abs(p)",),
        "M": ("u*w", "u*q", "v*p", "p*r", "w*abs(w)", "q*abs(q)"),
        "N": ("u*v", "u*r", "w*p", "p*q", "v*abs(v)", "r*abs(r)"),
    },
    # Pitch & Yaw (McCarter sec. 3.2.3, eqs 3.26-3.31; Appendix D Table D.3; Tables E.4-E.5). K is
    # identically zero (eq. 3.29). Per force 32/17/17/0/17/17 = 100 = Table 5.1 n.
    "pitch_yaw": {
        "X": (
            "u", "v", "w", "q", "r", "abs(v)", "abs(w)", "abs(q)", "abs(r)", "u*u", "u*v", "u*w",
            "u*r", "v*v", "v*r", "w*w", "w*q", "q*q", "r*r", "u*abs(v)", "u*abs(w)", "u*abs(q)",
            "u*abs(r)", "v*abs(v)", "v*abs(r)", "w*abs(w)", "w*abs(q)", "q*abs(u)", "q*abs(w)",
            "q*abs(q)", "r*abs(v)", "r*abs(r)",
        ),
        "Y": (
            "v", "r", "abs(u)", "abs(v)", "abs(r)", "u*u", "u*v", "u*r", "v*v", "v*r", "r*r",
            "u*abs(v)", "u*abs(r)", "v*abs(v)", "v*abs(r)", "r*abs(v)", "r*abs(r)",
        ),
        "Z": (
            "w", "q", "abs(u)", "abs(w)", "abs(q)", "u*u", "u*w", "u*q", "w*w", "w*q", "q*q",
            "u*abs(w)", "u*abs(q)", "w*abs(w)", "w*abs(q)", "q*abs(w)", "q*abs(q)",
        ),
        "K": (),
        "M": (
            "w", "q", "abs(u)", "abs(w)", "abs(q)", "u*u", "u*w", "u*q", "w*w", "w*q", "q*q",
            "u*abs(w)", "u*abs(q)", "w*abs(w)", "w*abs(q)", "q*abs(w)", "q*abs(q)",
        ),
        "N": (
            "v", "r", "abs(u)", "abs(v)", "abs(r)", "u*u", "u*v", "u*r", "v*v", "v*r", "r*r",
            "u*abs(v)", "u*abs(r)", "v*abs(v)", "v*abs(r)", "r*abs(v)", "r*abs(r)",
        ),
    },
    # Linear (McCarter sec. 3.2.4, eqs 3.32-3.33; Appendix D Table D.5; Table E.7): full 6x6 K_nu.
    # Per force 6 x 6 = 36 = Table 5.1 n.
    "linear": {force: DOFS for force in FORCES},
    # McFarland & Whitcomb (McCarter sec. 3.2.5, eq. 3.34; Appendix D Tables D.1-D.2; Tables
    # E.1-E.3): all 36 sign-preserving quadratics a*abs(b) (basis block C.4) in every force. Eq.
    # 3.34 prints K diag(nu)|nu| (a 6-vector); the 6x36 coefficient matrix shows it means K (nu kron
    # |nu|). Per force 36 x 6 = 216 = Table 5.1 n.
    "mcfarland": {force: _SIGN_PRESERVING for force in FORCES},
    # Uncoupled (McCarter sec. 3.2.6, eqs 3.35-3.40; Appendix D Table D.8; Table E.10): a, a*a,
    # abs(a), a*abs(a) with a the velocity of the force axis. 4 x 6 = 24 = Tables 5.1/5.2 n. NOTE:
    # the Fig. 5.14 caption says n = 22 and Table E.10 lists 22 coefficients, omitting X_u and
    # X_{u|u|}: with u > 0 throughout the data, u == abs(u) and u*u == u*abs(u), so those columns
    # alias (E.10 X_{|u|} = -7.690, X_{uu} = -1.288 equal Fossen X_u, X_{u|u|} of Table E.11
    # exactly).
    "uncoupled": {
        "X": ("u", "abs(u)", "u*u", "u*abs(u)"),
        "Y": ("v", "abs(v)", "v*v", "v*abs(v)"),
        "Z": ("w", "abs(w)", "w*w", "w*abs(w)"),
        "K": ("p", "abs(p)", "p*p", "p*abs(p)"),
        "M": ("q", "abs(q)", "q*q", "q*abs(q)"),
        "N": ("r", "abs(r)", "r*r", "r*abs(r)"),
    },
    # Fossen (McCarter sec. 3.2.7, eq. 3.41; Appendix D Table D.9; Table E.11): a and a*abs(a) per
    # axis (eq. 3.41 should read diag(.) nu + diag(.) diag(|nu|) nu). 2 x 6 = 12 = Table 5.1 n.
    "fossen": {
        "X": ("u", "u*abs(u)"),
        "Y": ("v", "v*abs(v)"),
        "Z": ("w", "w*abs(w)"),
        "K": ("p", "p*abs(p)"),
        "M": ("q", "q*abs(q)"),
        "N": ("r", "r*abs(r)"),
    },
    # Coe (McCarter sec. 3.2.8, eqs 3.42-3.44; Appendix D Table D.6; Table E.8). Follows Table D.6
    # (33 = Table 5.1 n; Table E.8 has exactly these 33). Eq. 3.44 also lists X_{u|u|}, Z_{u|u|},
    # M_{u|u|} (36 terms); McCarter dropped them, as for u > 0 u*abs(u) aliases u*u (already
    # present). Per force 8/3/8/3/8/3 = 33.
    "coe": {
        "X": ("u*u", "v*v", "w*w", "p*p", "q*q", "r*r", "w*abs(w)", "q*abs(q)"),
        "Y": ("v*abs(v)", "p*abs(p)", "r*abs(r)"),
        "Z": ("u*u", "v*v", "w*w", "p*p", "q*q", "r*r", "w*abs(w)", "q*abs(q)"),
        "K": ("v*abs(v)", "p*abs(p)", "r*abs(r)"),
        "M": ("u*u", "v*v", "w*w", "p*p", "q*q", "r*r", "w*abs(w)", "q*abs(q)"),
        "N": ("v*abs(v)", "p*abs(p)", "r*abs(r)"),
    },
    # Weiss eq. 45 (not McCarter): diagonal quadratic drag a*abs(a) per axis. 6 terms.
    "weiss_quadratic": {
        "X": ("u*abs(u)",),
        "Y": ("v*abs(v)",),
        "Z": ("w*abs(w)",),
        "K": ("p*abs(p)",),
        "M": ("q*abs(q)",),
        "N": ("r*abs(r)",),
    },
}
# fmt: on

# Model complexity n-bar as reported by McCarter, Tables 5.1 and 5.2 ("n" column).
MASK_TERM_COUNTS: dict[str, int] = {
    "gertler_hagen": 88,
    "prestero": 30,
    "pitch_yaw": 100,
    "linear": 36,
    "mcfarland": 216,
    "uncoupled": 24,  # Tables 5.1/5.2; the Fig. 5.14 caption and Table E.10 give 22 (see above)
    "fossen": 12,
    "coe": 33,  # Tables 5.1/5.2 and Table D.6; eq. 3.44 as printed would give 36 (see above)
    "weiss_quadratic": 6,  # not in McCarter: Weiss eq. 45, one term per axis
}
