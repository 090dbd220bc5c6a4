"""Models: the damping basis library and (later) parametric, NARX and hybrid models."""
