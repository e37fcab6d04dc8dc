"""Shared test setup: float64 everywhere (tests only: library code never changes JAX's config)."""

import jax

jax.config.update("jax_enable_x64", True)
