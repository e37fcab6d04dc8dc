"""Shared test setup: float64 everywhere (tests only: library code never changes JAX's config)."""

import jax

jax.config.update("jax_enable_x64", True)

from hypothesis import settings  # noqa: E402

# Deterministic property tests in CI: the same examples on every run.
settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True)
settings.load_profile("ci")

# The CLI caches compilations in the user's cache directory by default (cli.cache): the tests' CLI runs
# (in-process and subprocesses) run without it unless a test passes --cache-dir.
import os  # noqa: E402

os.environ["STIEFEL_CACHE_DIR"] = "off"
