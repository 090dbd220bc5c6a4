"""Fossen 6-DOF physics, batched over leading dimensions, float64 and differentiable (PyTorch).

Each term exists once here; regression forms, simulators, hybrids and the fault detector use it.
"""
