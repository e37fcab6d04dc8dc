"""Optimisation on generalised Stiefel manifolds ``{X : XᵀMX = I}`` in JAX."""
