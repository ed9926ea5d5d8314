"""Results are written atomically, and nothing is lost silently (docs/cli.md#the-command-line-and-set-up).

- A result (file or folder) is built under a hidden name beside its target and appears complete
  or not at all; an existing result is replaced only when asked (``force``), and the replacement
  is an atomic exchange (Linux ``renameat2(RENAME_EXCHANGE)``): at every instant the target holds
  the complete old or the complete new result.
- :func:`reserve` takes an exclusive lock on the target (``flock`` on a hidden lock file beside
  it) before the work: of several runs writing the same place at once one proceeds, the others
  get a ``UsageError`` (exit 2). Taking the lock is also the check that the place is writable,
  so an unwritable output is reported before the work, not after it.
- Hidden entries ``.NAME.brdffit-*`` are this module's. A run killed at any point can leave some
  behind; the next run on the same target, holding the lock, removes them (and puts back an old
  result that a non-atomic fallback swap had set aside).
- What a file holds is valid for its format whatever the data: :func:`json_text` writes strict
  JSON (a non-finite number is null), :func:`plain_text` removes the characters no text file may
  hold (controls, lone surrogates) from names written into files.
- The ``brdffit`` executable's Ctrl-C (``brdffit._interrupt``) ends the process at once and removes
  what this run wrote (:func:`remove_this_runs_outputs`), its scratch folders (:func:`scratch_dir`)
  and its helper processes (:func:`start_process`) included.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import fcntl
import json
import math
import os
import re
import shutil
import tempfile
import threading
from pathlib import Path

from .errors import InputError, UsageError

_MARK = ".brdffit-"
_RENAME_NOREPLACE, _RENAME_EXCHANGE = 1, 2
_AT_FDCWD = -100
#: targets this process holds a lock on: absolute path -> nesting count
_HELD: dict[str, int] = {}
_HELD_GUARD = threading.Lock()
#: Set when the user asked this run to stop (the CLI's Ctrl-C handler sets it, then raises). The
#: raised exception can be lost: Python only prints ("Exception ignored in ...") an exception raised
#: inside a garbage-collection callback or a ``__del__``, and a signal's handler runs wherever the
#: interpreter happens to be (seen: inside JAX's ``_xla_gc_callback``; the fit then went on and
#: wrote its result). So nothing is committed once this is set, whatever became of the exception.
STOP_REQUESTED = threading.Event()
#: What this process writes, for the ``brdffit`` executable's Ctrl-C (:func:`remove_this_runs_outputs`):
#: the targets it holds a lock on (absolute paths; their lock files are ``_LOCKS``) and the results it has committed.
#: ``_GUARD`` is held while either changes and for a whole commit, so that an interrupt handled in
#: another thread sees a result either not yet committed or committed and listed, never half-way.
_GUARD = threading.RLock()
_RESERVED: set[str] = set()
#: Lock files this process has opened and not yet closed (descriptor -> path), listed in the same step as
#: they are made (under ``_GUARD``): an interrupt between making one and listing its target in
#: ``_RESERVED`` (seen in CI: Ctrl-C as the lock was being taken) still finds it.
_LOCKS: dict[int, Path] = {}
_COMMITTED: list[Path] = []
#: Targets whose commit completes a result of several files (:func:`complete_with`): once one is
#: committed, everything committed before it stays, whatever interrupts the run afterwards.
_COMPLETING: set[Path] = set()
#: This run's scratch folders (:func:`scratch_dir`) and files (:func:`scratch_file`) and helper processes
#: (:func:`start_process`), stopped and removed by :func:`remove_this_runs_outputs` (also under ``_GUARD``).
_SCRATCH: list[Path] = []
_PROCESSES: list = []


def read_input(path: str | os.PathLike, expected: str) -> bytes:
    """The bytes of the input file ``path``, or one ``InputError`` naming it: a folder where a file
    (``expected``, e.g. "a fit file (JSON)") was expected, or a file that cannot be read."""
    path = Path(path)
    if path.is_dir():
        raise InputError(path, f"is a folder, not {expected}")
    try:
        return path.read_bytes()
    except OSError as exc:
        raise InputError(path, f"cannot read: {exc.strerror or exc}") from None


def _hidden(path: Path, what: str) -> str:
    return f".{path.name}{_MARK}{what}"


def _usual_mode(path: Path, folder: bool) -> None:
    """mkstemp/mkdtemp create 0600/0700 entries; a result gets the usual permissions (umask)."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(path, (0o777 if folder else 0o666) & ~umask)


def check_target(path: str | os.PathLike, force: bool, folder: bool | None = None) -> Path:
    """``path`` may be written: it does not exist (or ``force``), it is of the right kind
    (``folder`` True/False; None: either), and no part of its parent is a file."""
    path = Path(path)
    if path.absolute().name in ("", ".", "..") or path.absolute() == Path.cwd():
        raise UsageError(f"{path}: name a new output inside a folder, not the folder itself")
    for parent in path.absolute().parents:
        if parent.exists():
            if not parent.is_dir():
                raise UsageError(f"{path}: cannot write here, {parent} is a file, not a folder")
            break
    if path.is_symlink() or path.exists():
        if folder is False and path.is_dir():
            raise UsageError(f"{path}: is a folder; the output here is a file (give a file name)")
        if folder is True and not path.is_dir():
            raise UsageError(f"{path}: is a file; the output here is a folder")
        if not force:
            raise UsageError(f"{path}: already exists (use --force to replace it)")
    return path


def _rename2(src: Path, dst: Path, flags: int) -> bool:
    """``renameat2``; False where the system or the file system does not offer it."""
    try:
        fn = ctypes.CDLL(None, use_errno=True).renameat2
    except (AttributeError, OSError):
        return False
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    if fn(_AT_FDCWD, os.fsencode(src), _AT_FDCWD, os.fsencode(dst), flags) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):
        return False
    if err == errno.EEXIST:
        raise UsageError(f"{dst}: already exists (use --force to replace it)")
    raise OSError(err, os.strerror(err), str(dst))


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        with contextlib.suppress(FileNotFoundError):
            path.unlink()


def _commit(tmp: Path, path: Path, force: bool) -> None:
    """Move the finished ``tmp`` onto ``path``; the target is never missing or partial."""
    with _GUARD:
        _commit_guarded(tmp, path, force)
        _COMMITTED.append(path.absolute())
        if path.absolute() in _COMPLETING:  # in the same guarded step: no moment sees it half kept
            _COMPLETING.discard(path.absolute())
            _COMMITTED.clear()


def _commit_guarded(tmp: Path, path: Path, force: bool) -> None:
    if STOP_REQUESTED.is_set():
        raise KeyboardInterrupt  # the stop request's own exception was swallowed on the way
    if not (path.is_symlink() or path.exists()):
        if not _rename2(tmp, path, _RENAME_NOREPLACE):
            os.rename(tmp, path)
        return
    if not force:
        raise UsageError(f"{path}: already exists (use --force to replace it)")
    if tmp.is_file() and path.is_file():
        os.replace(tmp, path)  # atomic for files
        return
    if _rename2(tmp, path, _RENAME_EXCHANGE):  # tmp now holds the old result
        _remove(tmp)
        return
    # no atomic exchange here: set the old result aside under a name the next run restores from
    old = path.parent / (_hidden(path, "old-") + os.urandom(4).hex())
    os.rename(path, old)
    os.rename(tmp, path)
    _remove(old)


def _clean_leftovers(path: Path) -> None:
    """Remove what killed runs left beside ``path`` (the caller holds the lock)."""
    prefix = f".{path.name}{_MARK}"
    lock = _hidden(path, "lock")
    leftovers = [p for p in path.parent.iterdir() if p.name.startswith(prefix) and p.name != lock]
    olds = sorted(p for p in leftovers if p.name.startswith(_hidden(path, "old-")))
    if olds and not (path.is_symlink() or path.exists()):
        os.rename(olds[0], path)  # a complete old result set aside by a swap that was cut short
        leftovers.remove(olds[0])
    for p in leftovers:
        _remove(p)


@contextlib.contextmanager
def reserve(path: str | os.PathLike, force: bool = False, folder: bool | None = None):
    """Hold ``path`` for this run: checked, its parent created and writable, locked against other
    runs, leftovers of killed runs removed. Nested calls for the same path share the lock."""
    path = check_target(path, force, folder)
    key = os.path.abspath(path)
    with _HELD_GUARD:
        nested = key in _HELD
        if nested:
            _HELD[key] += 1
    if nested:
        try:
            yield path
        finally:
            with _HELD_GUARD:
                _HELD[key] -= 1
        return
    parent = Path(key).parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
        lock = parent / _hidden(path, "lock")
        with _GUARD:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
            _LOCKS[fd] = lock
    except OSError as exc:
        raise UsageError(f"{path}: cannot write here ({exc.strerror or exc}: {exc.filename or parent})") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            raise UsageError(f"{path}: another brdffit run is writing it now") from None
        # its previous holder may have removed the lock file between our open() and flock()
        if not _same_file(fd, lock):
            raise UsageError(f"{path}: another brdffit run is writing it now")
        _clean_leftovers(path)
        check_target(path, force, folder)  # again, now that no other run can change it
        with _HELD_GUARD, _GUARD:
            _HELD[key] = 1
            _RESERVED.add(key)
        try:
            yield path
        finally:
            with _HELD_GUARD, _GUARD:
                _HELD.pop(key, None)
                _RESERVED.discard(key)
    finally:
        _release(fd, lock)


def _same_file(fd: int, path: Path) -> bool:
    mine = os.fstat(fd)
    try:
        now = os.stat(path)
    except FileNotFoundError:
        return False
    return (now.st_ino, now.st_dev) == (mine.st_ino, mine.st_dev)


def _release(fd: int, lock: Path) -> None:
    """Remove the lock file if this run holds its lock or can take it, then close it. Taking it
    here covers a run interrupted between open() and flock(), which would otherwise leave the file
    behind; a lock another run holds, or a file another run made since, is left alone. (A run that
    opened the file meanwhile sees, once it has the lock, that the file at the path is not its own.)"""
    with _GUARD:
        try:
            _remove_lock_file(fd, lock)
        finally:
            _LOCKS.pop(fd, None)
            os.close(fd)


def _remove_lock_file(fd: int, lock: Path) -> None:
    """Remove ``lock`` (opened as ``fd``) if this run holds its lock or can take it."""
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        if _same_file(fd, lock):
            os.unlink(lock)
    except OSError:
        pass  # another run holds it, or it is gone already


@contextlib.contextmanager
def _atomic(path: Path, force: bool, folder: bool, make_tmp):
    """Reserve ``path``, yield the temporary entry ``make_tmp(path)`` made beside it, commit it onto
    ``path`` on success; the temporary entry is removed in every case."""
    with reserve(path, force, folder=folder):
        tmp = make_tmp(path)
        try:
            _usual_mode(tmp, folder=folder)
            yield tmp
            _commit(tmp, path, force)
        finally:
            _remove(tmp)


def _new_file(path: Path, suffix: str | None) -> Path:
    fd, name = tempfile.mkstemp(prefix=_hidden(path, "new-"), suffix=suffix or path.suffix, dir=path.absolute().parent)
    os.close(fd)
    return Path(name)


@contextlib.contextmanager
def atomic_file(path: str | os.PathLike, force: bool = False, suffix: str | None = None):
    """Yield a temporary path beside ``path``; on success it is renamed onto ``path``."""
    with _atomic(Path(path), force, False, lambda p: _new_file(p, suffix)) as tmp:
        yield tmp


@contextlib.contextmanager
def atomic_dir(path: str | os.PathLike, force: bool = False):
    """Yield a temporary folder beside ``path``; on success it replaces ``path`` as a whole."""
    make = lambda p: Path(tempfile.mkdtemp(prefix=_hidden(p, "new-"), dir=p.absolute().parent))  # noqa: E731
    with _atomic(Path(path), force, True, make) as tmp:
        yield tmp


def forget_committed() -> None:
    """Start a new command: what was committed before is not this command's to remove (nor does a
    result an earlier command marked with :func:`complete_with` complete one of this command's)."""
    with _GUARD:
        _COMMITTED.clear()
        _COMPLETING.clear()


def complete_with(path: str | os.PathLike) -> None:
    """The commit of ``path`` will complete a result of several files (a BTF material's outputs, whose
    ``params.exr`` is written last): from that commit on, an interrupt keeps everything committed so
    far. Marked before the work, so that there is no moment between the last file and the keeping."""
    with _GUARD:
        _COMPLETING.add(Path(path).absolute())


def remove_this_runs_outputs(timeout: float = 10.0) -> None:
    """For an interrupt that ends the process at once (the ``brdffit`` executable's Ctrl-C, handled in
    a thread while the work may be anywhere, even inside a compiler): remove every result this
    command committed, every temporary entry beside a target it holds, and their lock files. Waits
    up to ``timeout`` s for a commit in progress; the caller then ends the process (``os._exit``),
    so ``_GUARD`` stays held and nothing is committed after this."""
    _GUARD.acquire(timeout=timeout)
    for proc in _PROCESSES:  # first, so that none writes into a scratch folder being removed
        with contextlib.suppress(OSError):
            proc.kill()
        with contextlib.suppress(Exception):
            proc.wait(timeout=timeout)
    for path in _SCRATCH:
        _remove(path)
    for path in _COMMITTED:
        _remove(path)
    for key in list(_RESERVED):
        path = Path(key)
        for entry in path.parent.glob(f"{_hidden(path, 'new-')}*"):
            _remove(entry)
    for fd, lock in list(_LOCKS.items()):  # held, or made and about to be taken
        _remove_lock_file(fd, lock)


# -- scratch folders and helper processes ---------------------------------------------------------
def scratch_dir(prefix: str) -> Path:
    """A new private folder in the system's temporary folder for this run's intermediate files;
    the caller removes it (:func:`remove_scratch`), a Ctrl-C of the executable does too. Made and
    listed in one step, so that no moment of an interrupt leaves it behind."""
    with _GUARD:
        path = Path(tempfile.mkdtemp(prefix=prefix))
        _SCRATCH.append(path)
    return path


def remove_scratch(path: Path) -> None:
    with _GUARD:
        shutil.rmtree(path, ignore_errors=True)
        with contextlib.suppress(ValueError):
            _SCRATCH.remove(path)


@contextlib.contextmanager
def scratch_file(path: Path):
    """For a ``with`` block that writes ``path`` and renames it to its final name (a BTF's tile cache, a
    tile's file): the file is listed as this run's scratch while the block runs, so that a Ctrl-C of the
    executable removes it too, and it is removed when the block ends without renaming it (an error)."""
    with _GUARD:
        _SCRATCH.append(path)
    try:
        yield path
    finally:
        with _GUARD:
            _remove(path)
            with contextlib.suppress(ValueError):
                _SCRATCH.remove(path)


@contextlib.contextmanager
def scratch(prefix: str):
    """A scratch folder (:func:`scratch_dir`) for a ``with`` block, removed after it. In place of
    ``tempfile.TemporaryDirectory``, whose folder a Ctrl-C of the executable (which ends the process at
    once: no ``with`` block ends) would leave behind."""
    path = scratch_dir(prefix)
    try:
        yield path
    finally:
        remove_scratch(path)


def start_process(argv: list[str], **popen_options):
    """``subprocess.Popen(argv, **popen_options)``, a helper process of this run: in a session of
    its own (a terminal's Ctrl-C reaches brdffit, which stops it before removing its scratch
    folders, rather than the helper dying on its own while it writes), and listed in the same step
    as it starts. :func:`forget_process` once it has ended."""
    import subprocess

    with _GUARD:
        proc = subprocess.Popen(argv, start_new_session=True, **popen_options)
        _PROCESSES.append(proc)
    return proc


def forget_process(proc) -> None:
    with _GUARD, contextlib.suppress(ValueError):
        _PROCESSES.remove(proc)


# -- what a file may hold ---------------------------------------------------------------------------
#: Characters no text file of brdffit's formats may hold: XML 1.0 forbids the C0 controls other than
#: tab, newline and carriage return, lone surrogates, U+FFFE and U+FFFF (and UTF-8 cannot encode a
#: lone surrogate at all); DEL and the C1 controls are discouraged and never part of a name.
_NOT_TEXT = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\x7f-\x9f\ud800-\udfff\ufffe\uffff]")
_SURROGATE = re.compile("[\ud800-\udfff]")


def plain_text(text) -> str:
    """``str(text)`` with every character no text file may hold (see ``_NOT_TEXT``) replaced by
    U+FFFD: a name taken from data (a measurement's, a fit's) written into any file."""
    return _NOT_TEXT.sub("\ufffd", str(text))


def strict_json(value):
    """``value`` as strict JSON holds it: a non-finite number (NaN, inf) becomes null, tuples and
    NumPy arrays lists, NumPy scalars numbers; a lone surrogate in a string (valid Python, not
    Unicode: a UTF-8 reader refuses it) becomes U+FFFD (JSON escapes the controls)."""
    if value is None or isinstance(value, bool | int):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, str):
        return _SURROGATE.sub("\ufffd", value)
    if isinstance(value, dict):
        return {strict_json(str(k)): strict_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [strict_json(v) for v in value]
    if hasattr(value, "tolist"):  # NumPy arrays and scalars
        return strict_json(value.tolist())
    raise TypeError(f"no JSON form for {type(value).__name__} {value!r:.60}")


def json_text(value, indent: int | None = None, sort_keys: bool = False) -> str:
    """Strict JSON text of ``value`` (:func:`strict_json`): any JSON reader takes it."""
    return json.dumps(strict_json(value), indent=indent, sort_keys=sort_keys, allow_nan=False)
