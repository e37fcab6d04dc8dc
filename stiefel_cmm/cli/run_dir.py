"""One run's output directory, written all or nothing by one run at a time.

``RunDir(path, command, outputs=…, owned=…)`` is a context manager:

* entering validates ``path`` (created if missing; a file or an unwritable folder is refused),
  takes ``path/.stiefel.lock`` (``fcntl.flock``; the kernel releases it when the process dies),
  refuses a folder whose ``summary.json`` belongs to another command or that holds an output name
  no stiefel run wrote, and removes what a killed run left behind;
* ``write(role, name, fill)`` stages a file in ``path/.stiefel-staging-<pid>-<random>/`` (flushed
  and fsynced) and records its size and SHA-256; an ``OSError`` becomes ``OutputError``
  (``could not write …: No space left on device``) with the staged file removed;
* ``commit(summary)`` swaps the run in with SIGINT/SIGTERM held back: (a) the old ``summary.json``
  goes, (b) then the files of the old run that this run does not make, (c) the new files are
  renamed in, (d) ``summary.json`` comes last, its ``files`` listing exactly them:
  ``{role: {"name", "bytes", "sha256"}}``, and its ``other_files`` naming what else the folder holds
  (files no stiefel run listed: left as they are). ``.stiefel-commit.json`` names every file involved
  while the commit runs, so a run killed there leaves the next run knowing what is stiefel's;
* ``amend()`` instead adds the staged files to a finished run (``stiefel view DIR`` writes ``view.html``
  this way): they are moved in and listed in its ``summary.json``, the run's files stay — and the next
  run into the folder removes them with the rest of the old run at (b);
* leaving removes the staging folder and releases the lock, whatever happened.

Files that no stiefel run listed are never touched.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import shutil
import signal
import stat
import threading
import uuid
from pathlib import Path
from typing import Any, BinaryIO, Callable, Iterable, Iterator

__all__ = ["RunDir", "OutputError", "SUMMARY", "LOCK", "STAGING_PREFIX", "JOURNAL"]

SUMMARY = "summary.json"
LOCK = ".stiefel.lock"
STAGING_PREFIX = ".stiefel-staging-"
JOURNAL = ".stiefel-commit.json"


class OutputError(Exception):
    """The output directory cannot be used or written; reported as one line, exit code 1."""


def _reason(e: OSError) -> str:
    return e.strerror or str(e)


def _write_all(fd: int, data: Any) -> int:
    """Write all of ``data`` (a bytes-like object) to ``fd``: the one place staged bytes reach the disk."""
    view = memoryview(data).cast("B")
    done = 0
    while done < len(view):
        done += os.write(fd, view[done:])
    return done


class _Raw(io.RawIOBase):
    """A writable, seekable raw file over ``fd`` whose writes go through ``_write_all``."""

    def __init__(self, fd: int) -> None:
        super().__init__()
        self._fd, self.discard = fd, False

    def writable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def fileno(self) -> int:
        return self._fd

    def write(self, b: Any) -> int:
        if self.discard:  # the file is being thrown away: drop what the buffer still holds
            return memoryview(b).nbytes
        return _write_all(self._fd, b)

    def seek(self, pos: int, whence: int = 0) -> int:
        return os.lseek(self._fd, pos, whence)


@contextlib.contextmanager
def _staged_file(path: Path) -> Iterator[BinaryIO]:
    """A new file at ``path`` (must not exist), buffered; flushed and fsynced before it is closed."""
    fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), 0o644)
    raw = _Raw(fd)
    fh = io.BufferedWriter(raw, buffer_size=1 << 20)
    try:
        yield fh  # type: ignore[misc]
        fh.flush()
        os.fsync(fd)
    except BaseException:
        raw.discard = True
        raise
    finally:
        with contextlib.suppress(Exception):
            fh.close()
        os.close(fd)


def _fsync_path(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_dir(path: Path) -> None:
    """Best effort: some file systems refuse fsync on a directory."""
    with contextlib.suppress(OSError):
        _fsync_path(path)


def _digest(path: Path) -> dict:
    h, size = hashlib.sha256(), 0
    with open(path, "rb") as fh:
        while chunk := fh.read(1 << 20):
            h.update(chunk)
            size += len(chunk)
    return {"bytes": size, "sha256": h.hexdigest()}


def _plain_name(name: Any) -> bool:
    """A file name stiefel may own: no folders, not hidden, not the summary."""
    return (isinstance(name, str) and name == Path(name).name and name not in ("", ".", "..")
            and not name.startswith(".") and name != SUMMARY)


def _listed_names(doc: dict) -> set[str]:
    """File names of a summary's or journal's ``files`` (role → name or ``{"name": …}``) or ``names``."""
    files = doc.get("files", {})
    values = files.values() if isinstance(files, dict) else []
    names = {v if isinstance(v, str) else v.get("name") if isinstance(v, dict) else None for v in values}
    names |= set(n for n in doc.get("names", []) if isinstance(n, str))
    return {n for n in names if _plain_name(n)}


@contextlib.contextmanager
def _hold_signals(signums: Iterable[int] = (signal.SIGINT, signal.SIGTERM)) -> Iterator[None]:
    """Hold SIGINT/SIGTERM back (blocked in this thread, deferred if another thread takes them); re-deliver after.

    Only on the main thread, where Python runs signal handlers; elsewhere a no-op.
    """
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    signums = tuple(signums)
    pending: list[int] = []
    old_mask = signal.pthread_sigmask(signal.SIG_BLOCK, signums)
    old = {s: signal.signal(s, lambda s, _f: pending.append(s)) for s in signums}
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h if h is not None else signal.SIG_DFL)
        signal.pthread_sigmask(signal.SIG_SETMASK, old_mask)
        for s in dict.fromkeys(pending):
            signal.raise_signal(s)


class RunDir:
    """The output directory of one ``stiefel`` run; see the module docstring.

    outputs: the names this run may write (checked on entry against files no stiefel run wrote);
    owned: names that always belong to this command (e.g. ``modes.partial.npz``), removed at commit;
    check: called just before the commit, raises to abandon it (e.g. an interrupt that was deferred).
    """

    def __init__(self, path: Path, command: str, *, outputs: Iterable[str] = (), owned: Iterable[str] = (),
                 check: Callable[[], None] | None = None) -> None:
        self.path, self.command, self.check = Path(path), command, check
        self.outputs, self.owned = tuple(outputs), tuple(owned)
        self.files: dict[str, dict] = {}
        self._old_names: set[str] = set()
        self._lock_fd: int | None = None
        self._staging: Path | None = None

    # ------------------------------------------------------------------ entry and exit

    def __enter__(self) -> RunDir:
        try:
            self._validate()
            self._lock()
            self._check_owner()
            self._remove_leftovers()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        with _hold_signals():
            self.close()

    def close(self) -> None:
        """Remove the staging folder, release the lock."""
        if self._staging is not None:
            shutil.rmtree(self._staging, ignore_errors=True)
            self._staging = None
        if self._lock_fd is not None:
            os.close(self._lock_fd)  # closing the descriptor releases the flock
            self._lock_fd = None

    def _validate(self) -> None:
        p = self.path
        if p.exists() and not p.is_dir():
            raise OutputError(f"--out {p} is a file, not a directory; give a directory (created if missing)")
        try:
            p.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise OutputError(f"cannot create the --out directory {p}: {_reason(e)}") from None
        if not os.access(p, os.W_OK | os.X_OK):
            raise OutputError(f"the --out directory {p} is not writable; choose another --out")

    def _lock(self) -> None:
        try:
            self._lock_fd = os.open(self.path / LOCK, os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0), 0o644)
        except OSError as e:
            raise OutputError(f"cannot write in the --out directory {self.path}: {_reason(e)}") from None
        try:
            import fcntl
        except ImportError:  # no flock (Windows): no protection against a second run
            return
        try:
            fcntl.flock(self._lock_fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise OutputError(f"another stiefel run is writing to {self.path} (it holds {self.path / LOCK}); "
                              "wait for it to finish or choose another --out") from None
        except OSError as e:
            raise OutputError(f"cannot lock {self.path / LOCK}: {_reason(e)}") from None

    def _read(self, name: str) -> dict | None:
        path = self.path / name
        if not path.exists():
            return None
        try:
            doc = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as e:
            reason = _reason(e) if isinstance(e, OSError) else "not valid JSON"
            raise OutputError(f"{path} is not a stiefel summary ({reason}); move it away or choose another "
                              "--out") from None
        if not isinstance(doc, dict) or not isinstance(doc.get("command"), str):
            raise OutputError(f"{path} is not a stiefel summary (no 'command'); move it away or choose another --out")
        return doc

    def _check_owner(self) -> None:
        summary, journal = self._read(SUMMARY), self._read(JOURNAL)
        owner = (summary or journal or {}).get("command")
        if owner is not None and owner != self.command:
            raise OutputError(f"{self.path} holds the outputs of 'stiefel {owner}' ({SUMMARY}); 'stiefel "
                              f"{self.command}' will not replace them: choose another --out (e.g. "
                              f"{self.path.name}-{self.command})")
        self._old_names = set().union(*(_listed_names(d) for d in (summary, journal) if d is not None))
        foreign = [n for n in self.outputs if n not in self._old_names and n not in self.owned
                   and os.path.lexists(self.path / n)]
        if foreign:
            raise OutputError(f"{self.path / foreign[0]} was not written by a finished stiefel run (not listed in "
                              f"{SUMMARY}); move it away or choose another --out")

    def _remove_leftovers(self) -> None:
        """Staging folders of killed runs (under the lock no other live run has any)."""
        for p in self.path.glob(STAGING_PREFIX + "*"):
            if p.is_dir() and not p.is_symlink():
                shutil.rmtree(p, ignore_errors=True)

    # ------------------------------------------------------------------ writing

    def _stage(self, name: str) -> Path:
        if self._lock_fd is None:
            raise RuntimeError("RunDir used outside its 'with' block")
        if self._staging is None:
            token = f"{os.getpid()}-{uuid.uuid4().hex[:8]}"
            try:
                self._staging = self.path / f"{STAGING_PREFIX}{token}"
                self._staging.mkdir()
            except OSError as e:
                self._staging = None
                raise OutputError(f"could not write {self.path / name}: {_reason(e)}") from None
        return self._staging / name

    def _fail(self, staged: Path, name: str, e: OSError) -> OutputError:
        with contextlib.suppress(OSError):
            staged.unlink()
        return OutputError(f"could not write {self.path / name}: {_reason(e)}")

    @contextlib.contextmanager
    def _staged_path(self, name: str) -> Iterator[Path]:
        """The staged path of ``name``; a failure removes it (an ``OSError`` becomes ``OutputError``)."""
        staged = self._stage(name)
        try:
            yield staged
        except OSError as e:
            raise self._fail(staged, name, e) from None
        except BaseException:
            staged.unlink(missing_ok=True)
            raise

    def write(self, role: str | None, name: str, fill: Callable[[BinaryIO], object]) -> None:
        """Stage ``name`` by ``fill(fh)`` on a binary file; listed under ``role`` (None: not listed)."""
        with self._staged_path(name) as staged, _staged_file(staged) as fh:
            fill(fh)
        if role is not None:
            self.files[role] = {"name": name, **_digest(staged)}

    def write_path(self, role: str, name: str, fill: Callable[[Path], object]) -> None:
        """Stage ``name`` by ``fill(path)`` for writers that want a path (e.g. a PNG renderer)."""
        with self._staged_path(name) as staged:
            fill(staged)
            _fsync_path(staged)
        self.files[role] = {"name": name, **_digest(staged)}

    def write_text(self, role: str | None, name: str, text: str) -> None:
        """Stage a UTF-8 text file."""
        self.write(role, name, lambda fh: fh.write(text.encode("utf-8")))

    # ------------------------------------------------------------------ commit

    def _stage_summary(self, text: str, names: set) -> tuple[Path, Path]:
        """Stage the summary ``text`` and the journal naming ``names`` (the files a crash may leave), then run the
        pre-commit check; returns ``(staging directory, run directory)``."""
        self.write_text(None, SUMMARY, text)
        self.write_text(None, JOURNAL, json.dumps({"command": self.command, "names": sorted(names)}) + "\n")
        assert self._staging is not None
        if self.check is not None:
            self.check()
        return self._staging, self.path

    def commit(self, summary: dict, encode: Callable[[dict], str]) -> dict:
        """Swap this run's files in and write ``summary.json`` (``summary`` plus ``files``) last.

        ``encode`` turns the summary into JSON text. Returns the summary as written.
        """
        new = [rec["name"] for rec in self.files.values()]
        stale = sorted((self._old_names | set(self.owned)) - set(new))
        doc = {**summary, "files": {role: dict(rec) for role, rec in self.files.items()},
               "other_files": self._others(set(new), set(stale))}
        staging, p = self._stage_summary(encode(doc), self._old_names | set(self.owned) | set(new))
        with _hold_signals():
            try:
                os.replace(staging / JOURNAL, p / JOURNAL)
                _fsync_dir(p)
                (p / SUMMARY).unlink(missing_ok=True)                                 # (a)
                for name in stale:                                                     # (b)
                    target = p / name
                    if os.path.lexists(target) and not stat.S_ISDIR(os.lstat(target).st_mode):
                        target.unlink()
                for name in new:                                                       # (c)
                    os.replace(staging / name, p / name)
                os.replace(staging / SUMMARY, p / SUMMARY)                             # (d)
                _fsync_dir(p)
                (p / JOURNAL).unlink(missing_ok=True)
            except OSError as e:
                raise OutputError(f"could not finish writing {p}: {_reason(e)} ({SUMMARY} is missing until a "
                                  "run completes)") from None
        return doc

    def _others(self, new: set[str], stale: set[str]) -> list[str]:
        """What the folder holds besides this run's files, ``summary.json``, hidden names and the stale files
        the commit removes: files no stiefel run listed (they stay; ``summary.json`` names them)."""
        try:
            entries = sorted(os.scandir(self.path), key=lambda e: e.name)
        except OSError:
            return []
        others = []
        for e in entries:
            if e.name.startswith(".") or e.name == SUMMARY or e.name in new:
                continue
            is_dir = e.is_dir(follow_symlinks=False)
            if e.name in stale and not is_dir:
                continue
            others.append(e.name + ("/" if is_dir else ""))
        return others

    def amend(self, encode: Callable[[dict], str]) -> dict:
        """Add the staged files to the finished run in the folder and list them in its ``summary.json``.

        For a command that adds to a run (``stiefel view DIR``): the run's own files stay as they are; the
        staged ones are moved in (with SIGINT/SIGTERM held back, ``.stiefel-commit.json`` naming them while it
        runs) and ``summary.json`` is rewritten last with them under ``files``. A name that is hidden,
        ``summary.json`` or a file the run lists under another role is refused (``OutputError``).
        Returns the summary as written."""
        summary = self._read(SUMMARY)
        if summary is None:
            raise OutputError(f"{self.path} holds no {SUMMARY}: there is no finished run to add files to")
        files = summary.get("files") if isinstance(summary.get("files"), dict) else {}
        for role, rec in self.files.items():
            name = rec["name"]
            if not _plain_name(name):
                raise OutputError(f"{self.path / name} cannot be listed in {SUMMARY} (a hidden name or the summary "
                                  "itself): choose another name")
            taken = [r for r, old in files.items() if r != role and isinstance(old, dict) and old.get("name") == name]
            if taken:
                raise OutputError(f"{self.path / name} is the run's own file ({taken[0]} in {SUMMARY}): it is not "
                                  "replaced; choose another name")
        doc = {**summary, "files": {**files, **{role: dict(rec) for role, rec in self.files.items()}}}
        new = [rec["name"] for rec in self.files.values()]
        if isinstance(doc.get("other_files"), list):  # a name this run now lists is no longer another file
            doc["other_files"] = [n for n in doc["other_files"] if n not in new]
        staging, p = self._stage_summary(encode(doc), self._old_names | set(new))
        with _hold_signals():
            try:
                os.replace(staging / JOURNAL, p / JOURNAL)
                _fsync_dir(p)
                for name in new:
                    os.replace(staging / name, p / name)
                os.replace(staging / SUMMARY, p / SUMMARY)
                _fsync_dir(p)
                (p / JOURNAL).unlink(missing_ok=True)
            except OSError as e:
                raise OutputError(f"could not finish writing {p}: {_reason(e)}") from None
        return doc
