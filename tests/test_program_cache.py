"""Stored solver programs (``stiefel.runtime.program_cache``): keys that pin the program, no store for code the
key cannot pin, the same answer from a stored program, and stored files verified by content (key and SHA-256):
another program's file, corrupt bytes and older formats rejected quietly and counted, read-only stores read."""

import errno
import functools
import hashlib
import json
import logging
import os
import shutil
import stat
import subprocess
import sys
import textwrap
from collections import Counter, OrderedDict

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from stiefel import program_cache as pc


def test_describe_pins_static_parts_and_refuses_unknown_code():
    from objectives.energy.energies import cmm_energy
    from stiefel.linalg.operators import SparseOperator
    from stiefel_cases import grid_laplacian

    W = grid_laplacian(5)
    a = np.full(25, 0.04)
    e1 = cmm_energy(SparseOperator.from_scipy(W), a, 1.0, smoothing="f6")
    e2 = cmm_energy(SparseOperator.from_scipy(2 * W), 2 * a, 3.0, smoothing="f6")  # other values
    e3 = cmm_energy(SparseOperator.from_scipy(W), a, 1.0, smoothing="f3")  # another smoothing
    e4 = cmm_energy(SparseOperator.from_scipy(grid_laplacian(6)), np.full(36, 1 / 36), 1.0, smoothing="f6")
    assert pc.describe(e1) == pc.describe(e2)  # runtime values do not matter, nor the host matrix
    assert pc.describe(e1) != pc.describe(e3)  # static fields do
    assert pc.describe(e1) != pc.describe(e4)  # shapes do
    assert pc.describe(e1.true_value) != pc.describe(e1.__call__)
    assert pc.describe((1.0, 2, "x", None)) == "(1.0,2,'x',None)"
    assert pc.describe(jnp.zeros((2, 3))) != pc.describe(jnp.zeros((2, 3), jnp.int32))

    def local(x):
        return x

    for bad in (lambda x: x, local, np.sum, functools.partial(local, 1), object(), jnp.sin):
        with pytest.raises(pc.Uncacheable):
            pc.describe(bad)
    assert pc.program_key(lambda x: x, ()) is None


@pytest.mark.filterwarnings("ignore:A JAX array is being set as static")
def test_arrays_in_static_fields_are_described_by_content():
    """A static field's arrays are constants of the traced program: their values are part of the key."""
    import equinox as eqx

    class Holder(eqx.Module):
        table: np.ndarray = eqx.field(static=True)
        x: jax.Array

    Holder.__module__ = "stiefel.tests_only"  # a module of this project, for describe
    one = Holder(np.arange(3.0), jnp.zeros(2))
    assert pc.describe(one) == pc.describe(Holder(np.arange(3.0), jnp.ones(2)))  # x is an input
    assert pc.describe(one) != pc.describe(Holder(np.arange(3.0) + 1, jnp.zeros(2)))  # table is a constant


@pytest.mark.skipif(bool(jax.config.jax_compilation_cache_dir), reason="JAX's persistent cache is on here")
def test_no_store_without_jax_cache_dir():
    from stiefel.solvers.driver import _init

    assert pc.store_dir() is None and pc.load_or_export(_init, (), None) is None


def test_the_source_digest_covers_the_project_sources():
    """Keys change with any edit of ``stiefel``, ``objectives`` or ``mesh`` (a digest of no files would not)."""
    assert pc._source_digest() != hashlib.blake2b(digest_size=16).hexdigest()


# Two small programs of this project (for ``describe``) with the same inputs and outputs, stored in a temporary
# store: in-process stand-ins for the solver's ``_init``/``_advance`` programs of two smoothings (tests/test_cli.py
# and the slow test below store the real ones).
def _double_sine(x):
    return 2.0 * jnp.sin(x)


def _shifted_cosine(x):
    return jnp.cos(x) - 1.0


_double_sine.__module__ = _shifted_cosine.__module__ = "stiefel.tests_only"
_X = np.linspace(0.0, 1.0, 5)


@pytest.fixture
def store(tmp_path, monkeypatch):
    """A program store of this test's own, with zero counts."""
    where = tmp_path / pc.SUBDIR
    monkeypatch.setattr(pc, "store_dir", lambda: where)
    monkeypatch.setattr(pc, "_MEMORY", OrderedDict())
    monkeypatch.setattr(pc, "STATS", dict.fromkeys(pc.STATS, 0))
    monkeypatch.setattr(pc, "REJECTIONS", Counter())
    return where


def _fresh(fn):
    """``fn(_X)`` through the store, as a new process would ask for it (nothing in memory)."""
    pc._MEMORY.clear()
    call = pc.load_or_export(fn, (_X,), 0)
    assert call is not None
    return np.asarray(call(_X))


def _file(fn):
    return pc.store_dir() / f"{pc.program_key(fn, (_X,))}.jaxexport"


def _counts():
    from stiefel_cmm.cli.common import _program_counts

    return _program_counts()


def test_a_stored_program_carries_its_key_and_digest_and_is_loaded(store):
    expected = np.asarray(_double_sine(_X))
    np.testing.assert_allclose(_fresh(_double_sine), expected, rtol=1e-15)
    data = _file(_double_sine).read_bytes()
    assert data.startswith(pc.MAGIC)
    header_line, program = data[len(pc.MAGIC):].split(b"\n", 1)
    header = json.loads(header_line)
    assert header["sha256"] == hashlib.sha256(program).hexdigest() and header["size"] == len(program)
    key = header["key"]
    assert key["name"] == pc.program_key(_double_sine, (_X,))
    assert key["program"].startswith("stiefel.tests_only._double_sine|")
    assert jax.__version__ in key["versions"] and key["sources"] == pc._source_digest() and key["library"]
    np.testing.assert_allclose(_fresh(_double_sine), expected, rtol=1e-15)
    pc.load_or_export(_double_sine, (_X,), 0)  # from memory
    assert _counts() == {"loaded": 1, "rejected": 0, "traced": 1, "stored": 1, "reused": 1, "rejected_reasons": {}}


def test_another_programs_file_under_this_key_is_rejected(store, capfd):
    """The issue's substitution (another smoothing's files copied over the default's keys): same shapes and
    dtypes, another program; it is rejected, the right program traced and stored over it."""
    _fresh(_double_sine), _fresh(_shifted_cosine)
    shutil.copyfile(_file(_shifted_cosine), _file(_double_sine))
    capfd.readouterr()
    np.testing.assert_allclose(_fresh(_double_sine), np.asarray(_double_sine(_X)), rtol=1e-15)
    assert capfd.readouterr().err == ""
    assert _counts() | {"reused": 0} == {"loaded": 0, "rejected": 1, "traced": 3, "stored": 3, "reused": 0,
                                         "rejected_reasons": {"another program's key": 1}}
    np.testing.assert_allclose(_fresh(_double_sine), np.asarray(_double_sine(_X)), rtol=1e-15)
    assert pc.STATS["loaded"] == 1  # the file was replaced by the right program


def _program_bytes(path):
    data = path.read_bytes()
    return data[data.index(b"\n", len(pc.MAGIC)) + 1:]


def _flip_mlir(program: bytes) -> bytes:
    """``program`` with a byte pair flipped inside its StableHLO module (what made MLIR print on stderr)."""
    from jax import export

    module = bytes(export.deserialize(bytearray(program)).mlir_module_serialized)
    at = program.index(module) + 100
    return program[:at] + bytes([program[at] ^ 0xFF, program[at + 1] ^ 0xFF]) + program[at + 2:]


def _corrupt(kind, path):
    data = path.read_bytes()
    if kind == "flipped bytes":  # the corruption: the header's SHA-256 no longer matches
        middle = len(data) - len(_program_bytes(path)) // 2
        path.write_bytes(data[:middle] + bytes([data[middle] ^ 0xFF, data[middle + 1] ^ 0xFF]) + data[middle + 2:])
    elif kind == "truncated":
        path.write_bytes(data[: len(data) - 40])
    elif kind == "older format":  # what earlier versions stored: the bare jax.export bytes
        path.write_bytes(_program_bytes(path))
    elif kind == "garbage":
        path.write_bytes(b"\0garbage")
    elif kind == "bad program, right digest":  # passes both checks; JAX's deserialiser fails (and prints)
        key = json.loads(data[len(pc.MAGIC):data.index(b"\n", len(pc.MAGIC))])["key"]
        path.write_bytes(pc._encode(key, _flip_mlir(_program_bytes(path))))


@pytest.mark.parametrize(("kind", "reason"), [("flipped bytes", "digest mismatch"), ("truncated", "digest mismatch"),
                                              ("older format", "unknown format"), ("garbage", "unknown format"),
                                              ("bad program, right digest", "undeserialisable")])
def test_a_corrupt_file_is_rejected_with_nothing_on_stderr(store, capfd, caplog, kind, reason):
    expected = np.asarray(_double_sine(_X))
    _fresh(_double_sine)
    _corrupt(kind, _file(_double_sine))
    capfd.readouterr()
    with caplog.at_level(logging.INFO, logger=pc.__name__):
        np.testing.assert_allclose(_fresh(_double_sine), expected, rtol=1e-15)
    assert capfd.readouterr().err == ""  # no MLIR text, no warning
    lines = [r.getMessage() for r in caplog.records if r.name == pc.__name__]
    assert len(lines) == 1 and "discarded" in lines[0] and "\n" not in lines[0]  # one line, when asked for
    assert _counts() | {"reused": 0} == {"loaded": 0, "rejected": 1, "traced": 2, "stored": 2, "reused": 0,
                                         "rejected_reasons": {reason: 1}}
    np.testing.assert_allclose(_fresh(_double_sine), expected, rtol=1e-15)
    assert pc.STATS["loaded"] == 1 and pc.STATS["rejected"] == 1  # replaced by a good file


def test_what_is_printed_while_a_good_program_is_read_is_passed_on(store, capfd, monkeypatch):
    """Output on file descriptor 2 while a program is read is held back (MLIR's errors for a bad one are
    dropped, above); for a good one it is passed on, as it may be another thread's."""
    from jax import export

    _fresh(_double_sine)
    real = export.deserialize

    def noisy(program):
        os.write(2, b"a line from elsewhere\n")
        return real(program)

    monkeypatch.setattr(export, "deserialize", noisy)
    capfd.readouterr()
    _fresh(_double_sine)
    assert capfd.readouterr().err == "a line from elsewhere\n" and pc.STATS["loaded"] == 1


def _check_read_only_store(store, capfd):
    """The store (holding ``_double_sine``'s program and an older-format file for ``_shifted_cosine``) can
    be read but not written: programs load, nothing is written, nothing is said."""
    before = {p.name: p.read_bytes() for p in store.iterdir()}
    capfd.readouterr()
    np.testing.assert_allclose(_fresh(_double_sine), np.asarray(_double_sine(_X)), rtol=1e-15)
    np.testing.assert_allclose(_fresh(_shifted_cosine), np.asarray(_shifted_cosine(_X)), rtol=1e-15)
    assert capfd.readouterr().err == ""
    assert {p.name: p.read_bytes() for p in store.iterdir()} == before  # not written, not even a temporary file
    assert _counts() | {"reused": 0} == {"loaded": 1, "rejected": 1, "traced": 1, "stored": 0, "reused": 0,
                                         "rejected_reasons": {"unknown format": 1}}


def _fill_store():
    _fresh(_double_sine), _fresh(_shifted_cosine)
    _corrupt("older format", _file(_shifted_cosine))
    for key in pc.STATS:
        pc.STATS[key] = 0
    pc.REJECTIONS.clear()


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="root ignores file permissions")
def test_a_read_only_store_is_read_not_written(store, capfd):
    _fill_store()
    modes = {p: p.stat().st_mode for p in [store, *store.iterdir()]}
    for p, mode in modes.items():
        p.chmod(mode & ~(stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH))
    try:
        _check_read_only_store(store, capfd)
    finally:
        for p, mode in modes.items():
            p.chmod(mode)


def test_a_store_that_refuses_writes_is_read_not_written(store, capfd, monkeypatch):
    """The same as the read-only store, where the file system refuses the writes (also as root)."""
    _fill_store()

    def refuse(*args, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system")

    monkeypatch.setattr(pc.tempfile, "mkstemp", refuse)
    _check_read_only_store(store, capfd)


@pytest.fixture
def jax_cache_config():
    """JAX's persistent-cache settings restored after the test (``stiefel_cmm.cli.cache.enable`` sets them)."""
    from stiefel_cmm.cli import cache

    names = ("jax_persistent_cache_min_compile_time_secs", "jax_persistent_cache_min_entry_size_bytes")
    saved = {name: getattr(jax.config, name) for name in names}
    yield cache
    cache.enable(None, True)
    for name, value in saved.items():
        jax.config.update(name, value)


def test_the_cli_reads_a_read_only_cache_directory(tmp_path, monkeypatch, jax_cache_config):
    """A directory that exists but cannot be written is used read-only, without a warning: JAX writes no
    executable (its minimum compile time for writing is infinite); one that cannot be created is a warning."""
    cache = jax_cache_config
    monkeypatch.setattr(cache, "_writable", lambda path: "Read-only file system")  # as root, too
    assert cache.enable(tmp_path, False) == (str(tmp_path), None)
    assert jax.config.jax_compilation_cache_dir == str(tmp_path)
    assert jax.config.jax_persistent_cache_min_compile_time_secs == float("inf")
    assert pc.store_dir() == tmp_path / pc.SUBDIR
    used, warning = cache.enable(tmp_path / "missing", False)
    assert used is None and "is not usable (Read-only file system); running without it" in warning
    assert not jax.config.jax_compilation_cache_dir
    monkeypatch.undo()
    assert cache.enable(tmp_path, False) == (str(tmp_path), None)  # writable again: JAX writes again
    assert jax.config.jax_persistent_cache_min_compile_time_secs == 0


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="root ignores file permissions")
def test_the_cli_reads_a_cache_directory_without_write_permission(tmp_path, jax_cache_config):
    tmp_path.chmod(0o555)
    try:
        assert jax_cache_config.enable(tmp_path, False) == (str(tmp_path), None)
        assert jax.config.jax_persistent_cache_min_compile_time_secs == float("inf")
    finally:
        tmp_path.chmod(0o755)


_RUN = textwrap.dedent("""
    import json, sys
    import jax
    jax.config.update("jax_enable_x64", True)
    if sys.argv[1] != "-":
        jax.config.update("jax_compilation_cache_dir", sys.argv[1])
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)
    import numpy as np, scipy.sparse as sp
    import jax.numpy as jnp
    sys.path.insert(0, "tests")
    from stiefel_cases import grid_laplacian
    from objectives.cmm.modes import compressed_modes
    from objectives.cmm.solvers import BlockCMM
    from stiefel import program_cache, minimize, GeneralizedStiefel, as_operator
    W = sp.csr_array(grid_laplacian(int(sys.argv[2])))
    a = np.full(W.shape[0], 1.0 / W.shape[0])
    # no saddle checks: the solver's two programs only (the checks' programs: test_saddle_check_programs_are_...)
    r = compressed_modes((W, a), 3, 2.0, solver=BlockCMM(max_iters=200, smoothing=sys.argv[3], saddle_checks=0))
    out = {"objective": r.objective, "iterations": r.iterations, **program_cache.STATS,
           "rejections": dict(program_cache.REJECTIONS), "sources": program_cache._source_digest()}
    if len(sys.argv) > 4:  # a user's own function: never stored
        Wop = as_operator(W, check=False, factor=False)
        S = GeneralizedStiefel(a, 2)
        before = dict(program_cache.STATS)
        res = minimize(lambda X: jnp.sum(X * Wop.mv(X)), S, S.random_point(jax.random.PRNGKey(0)), max_iters=20)
        out["user_function_stored"] = program_cache.STATS != before
    print(json.dumps(out))
""")


def _run(tmp_path, cache, m, smoothing="f6", *extra):
    """The counts and result of ``_RUN`` in a new process; nothing but JAX's own lines on its stderr."""
    script = tmp_path / "run.py"
    script.write_text(_RUN)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = {**os.environ, "PYTHONPATH": root}
    p = subprocess.run([sys.executable, str(script), str(cache), str(m), smoothing, *extra], cwd=root, env=env,
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    assert "error" not in p.stderr.lower() and "loc(" not in p.stderr, p.stderr[-2000:]  # no MLIR text
    return json.loads(p.stdout.strip().splitlines()[-1])


def _programs(cache) -> dict:
    """The stored files by the program they hold (``module.function`` of ``_init``/``_advance``)."""
    found = {}
    for path in (cache / pc.SUBDIR).glob("*.jaxexport"):
        data = path.read_bytes()
        key = json.loads(data[len(pc.MAGIC):data.index(b"\n", len(pc.MAGIC))])["key"]
        found.setdefault(key["program"].split("|")[0], []).append((key["program"], path))
    return found


@pytest.mark.slow  # seven processes (~50 s); test_buckets checks the loading of stored programs in the default run
def test_stored_programs_serve_new_processes_with_the_same_answer(tmp_path):
    cache = tmp_path / "cache"
    sources = set()

    def run(*args):
        out = _run(tmp_path, *args)
        sources.add(out["sources"])
        if len(sources) > 1:  # keys hold the source digest: an edit elsewhere in the tree changes them all
            pytest.skip("the project's sources were edited while this test ran")
        return out

    plain = run("-", 8)  # no cache: traced as usual
    assert plain["exported"] == plain["loaded"] == 0
    first = run(cache, 8, "f6", "user")
    assert first["exported"] == first["stored"] == 2 and first["loaded"] == 0 and first["memory"] >= 1
    assert not first["user_function_stored"]  # later stages came from memory; the user's function is not stored
    stored = sorted((cache / pc.SUBDIR).glob("*.jaxexport"))
    assert len(stored) == 2
    second = run(cache, 8)
    assert second["loaded"] == 2 and second["exported"] == second["rejected"] == 0
    for result in (first, second):
        assert result["iterations"] == plain["iterations"]
        assert result["objective"] == pytest.approx(plain["objective"], rel=1e-12)
    # another smoothing is another program
    other = run(cache, 8, "f1")
    assert other["exported"] == 2 and other["loaded"] == 0
    # the issue's substitution: f1's files copied over the f6 keys (same shapes and dtypes) are rejected
    for pairs in _programs(cache).values():
        assert len(pairs) == 2
        (f6, f6_path), (f1, f1_path) = sorted(pairs, key=lambda pair: "'f1'" in pair[0])
        assert "'f6'" in f6 and "'f1'" in f1
        shutil.copyfile(f1_path, f6_path)
    swapped = run(cache, 8)
    assert swapped["loaded"] == 0 and swapped["rejected"] == 2 and swapped["stored"] == 2
    assert swapped["rejections"] == {"another program's key": 2}
    assert swapped["iterations"] == plain["iterations"]
    assert swapped["objective"] == pytest.approx(plain["objective"], rel=1e-12)
    # a byte pair flipped in every stored program: rejected, nothing on stderr (checked by _run)
    for path in (cache / pc.SUBDIR).glob("*.jaxexport"):
        data = bytearray(path.read_bytes())
        data[len(data) // 2] ^= 0xFF
        data[len(data) // 2 + 1] ^= 0xFF
        path.write_bytes(bytes(data))
    flipped = run(cache, 8)
    assert flipped["loaded"] == 0 and flipped["rejected"] == 2 and flipped["rejections"] == {"digest mismatch": 2}
    assert flipped["objective"] == pytest.approx(plain["objective"], rel=1e-12)
    for path in stored:
        path.write_bytes(b"not a program")
    again = run(cache, 8)
    assert again["exported"] == again["rejected"] == 2 and again["rejections"] == {"unknown format": 2}
    assert again["objective"] == pytest.approx(plain["objective"], rel=1e-12)


@pytest.mark.slow
def test_saddle_check_programs_are_stored_and_loaded(store):
    """The saddle check's two programs (LOBPCG curvature, escape step) go through the store like the solver's:
    a second "process" loads both, untraced, with the same results (a weakly typed LOBPCG count once made the
    escape step's key differ between the process that compiled it and one that loaded it)."""
    from objectives.cmm import saddle
    from objectives.energy.energies import cmm_energy
    from stiefel import GeneralizedStiefel
    from stiefel.linalg.operators import SparseOperator
    from stiefel_cases import grid_laplacian

    W, a = grid_laplacian(6), np.full(36, 1 / 36)
    F = cmm_energy(SparseOperator.from_scipy(W), a, 1.0, smoothing="f6")
    S = GeneralizedStiefel(a, 3)
    X = S.random_point(jax.random.PRNGKey(0))
    runs = []
    for _ in range(2):
        pc._MEMORY.clear()  # as in a new process
        X_new, record, _, _ = saddle.check(F, S, X, None, width=1e-3, threshold=-np.inf)  # always steps
        runs.append((np.asarray(X_new), record["curvature"]))
    assert pc.STATS["stored"] == 2 and pc.STATS["loaded"] == 2 and pc.STATS["exported"] == 2
    assert np.array_equal(runs[0][0], runs[1][0]) and runs[0][1] == runs[1][1]
