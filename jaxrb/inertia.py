"""Inertia tensors (kg m^2), about the mass centre in body axes unless stated."""
