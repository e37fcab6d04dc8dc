"""Shared test setup: float64 everywhere (tests only: library code never changes JAX's config)."""

import os

# One BLAS thread per test worker: the workers already use every core, and OpenBLAS's own threads on top of
# them made small dense solves wait on each other (a 5 s generalised eigh took 0.2 s with one thread).
# Set before numpy is first imported, which reads it once.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

from hypothesis import settings  # noqa: E402

# Deterministic property tests in CI: the same examples on every run.
settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True)
settings.load_profile("ci")

# The CLI caches compilations in the user's cache directory by default (stiefel_cmm.cli.cache): the tests' CLI runs
# (in-process and subprocesses) run without it unless a test passes --cache-dir.

os.environ["STIEFEL_CACHE_DIR"] = "off"

# Every compiled XLA program keeps its machine code in memory maps of its own. The whole suite compiles
# thousands of programs; kept for the life of the process they exceeded Linux's default limit of 65530
# maps (vm.max_map_count) about 70 % of the way through, and LLVM then crashed (a segfault inside
# compilation). Compiled programs are therefore dropped after a test module once the process holds more than
# MAX_MAPS maps (a module adds ~5000). Dropping them after every module recompiled the programs that later
# modules share (the demo mesh's solvers, the CLI's): the suite took 831 s instead of 692 s (2 cores, 2026-11-26).
# Tests that compare a first compilation with a second clear JAX's caches themselves.
import gc  # noqa: E402

import pytest  # noqa: E402

MAX_MAPS = 30000


def _memory_maps() -> int:
    """Memory maps of this process (``/proc/self/maps``); where there is none, a count that releases every time."""
    try:
        with open("/proc/self/maps", "rb") as f:
            return sum(1 for _ in f)
    except OSError:  # not Linux: release after every module
        return 1 << 30


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs():
    yield
    if _memory_maps() > MAX_MAPS:
        jax.clear_caches()
        gc.collect()


# The heaviest modules first (longest-first packing onto the xdist workers, pyproject.toml: with whole
# modules per worker, a heavy module collected last would leave the other worker idle at the end).
_HEAVY_FIRST = ["test_block_solver.py", "test_cmm.py", "test_sequential_solver.py", "test_readme.py", "test_implicit.py",
                "test_cli.py", "test_smoothings.py", "test_geodesics.py", "test_objectives_energy.py",
                "test_retractions.py", "test_trust_region.py", "test_grassmann.py", "test_saddle.py",
                "test_operators.py"]


def pytest_collection_modifyitems(config, items):
    rank = {name: i for i, name in enumerate(_HEAVY_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: the order within a module kept


# Every mesh the tests need is generated or committed under tests/data/: with CI set, a test that skips for a
# missing mesh or file fails instead (as the 'browser' test does without Chromium, tests/test_viewer.py).
MISSING_FILE = ("not found", "not present", "shared mesh")


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item, call):
    report = yield
    if os.environ.get("CI") and report.skipped and not hasattr(report, "wasxfail"):
        reason = (report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr))
        reason = reason.removeprefix("Skipped: ")
        if any(word in reason.lower() for word in MISSING_FILE):
            report.outcome = "failed"
            report.longrepr = f"CI is set, and this test skipped for a missing file: {reason}"
    return report
