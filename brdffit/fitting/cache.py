"""Persistent compilation cache (docs/fitting.md#fitting): compiled solvers are kept on disk, so a second process
does not compile again.

In ``<user cache folder>/jax`` (``platformdirs.user_cache_dir("brdffit")``: ``~/.cache/brdffit``
on Linux, ``~/Library/Caches/brdffit`` on macOS); ``BRDFFIT_CACHE=DIR`` moves it,
``BRDFFIT_CACHE=off`` disables it. Two layers: the programs of library models (fit, start grid,
batch) are kept whole, compiled, by :func:`load_or_compile` (a second process loads them without tracing
or lowering); everything else goes through JAX's own persistent cache, enabled when
``brdffit.fitting`` is imported (before anything compiles), which keeps every compilation however
short (JAX keeps only those over 1 s by default; ours take 0.1-3 s each).

A kept program is found again by brdffit's fitting and model sources (their hash), the model's
name and the shapes, not by what its code computes: source that picks its behaviour at run time
from outside itself must run with the cache off. mutmut's copy is such source (one file holds
every mutant, chosen by ``MUTANT_UNDER_TEST``): with the cache on, every mutant loaded the first
program kept (``scripts/mutation_run.sh`` turns it off; JAX's own cache, keyed by the compiled
code, still serves there).
"""

from __future__ import annotations

import collections
import concurrent.futures
import contextlib
import os
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

_STATE = {"dir": None}


def cache_dir() -> Path | None:
    """Where compiled code is kept, or None when disabled."""
    env = os.environ.get("BRDFFIT_CACHE", "").strip()
    if env.lower() in ("off", "0", "none", "false", "no"):
        return None
    if env:
        return Path(env).expanduser()
    import platformdirs

    return Path(platformdirs.user_cache_dir("brdffit")) / "jax"


def enable() -> Path | None:
    """Point JAX's persistent compilation cache at ``cache_dir()`` (idempotent)."""
    import jax

    path = cache_dir()
    if path is None:
        return None
    if _STATE["dir"] == path:
        return path
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None  # a read-only home: compile every time rather than fail
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    _STATE["dir"] = path
    return path


def _listen_for_jax_hits() -> None:
    """Count JAX's persistent-cache hits (``load_or_compile`` must know whether JAX answered)."""
    import jax

    if "jax_hits" not in _STATE:
        _STATE["jax_hits"] = 0
        jax.monitoring.register_event_listener(_count_jax_cache_hits)


def _count_jax_cache_hits(event: str, **kwargs) -> None:
    if event == "/jax/compilation_cache/cache_hits":
        _STATE["jax_hits"] += 1


#: The compiled programs kept on disk (``load_or_compile``) are pruned, least recently used first,
#: when together they pass this size. A program takes 0.01-1.5 MB, and every brdffit version and
#: XLA_FLAGS setting keys its own: without a limit, programs no release will load again pile up.
PROGRAMS_MAX_BYTES = 512 * 2**20


def _prune(folder: Path, keep: Path) -> None:
    """Delete the least recently used programs in ``folder`` (a load marks its file used) until
    they take at most ``PROGRAMS_MAX_BYTES``; never ``keep`` (the program just written). Best
    effort: a file another process removed first, or a read-only folder, is passed over."""
    entries = []
    try:
        with os.scandir(folder) as it:
            for entry in it:
                if entry.name.endswith(".bin"):
                    try:
                        st = entry.stat()
                    except OSError:
                        continue
                    entries.append((st.st_mtime, st.st_size, entry.path))
    except OSError:
        return
    total = sum(size for _, size, _ in entries)
    for _, size, path in sorted(entries):  # oldest use first
        if total <= PROGRAMS_MAX_BYTES:
            break
        if path == str(keep):
            continue
        try:
            os.unlink(path)
        except OSError:
            continue
        total -= size


def cache_enabled() -> bool:
    return _STATE["dir"] is not None


def _library_model(model) -> bool:
    """A model whose formulas all live in brdffit (a user's own formula is not keyed on disk)."""
    parts = getattr(model, "components", ()) or (model,)
    return all(getattr(c.formula, "__module__", "").startswith("brdffit.") for c in parts)


def _source_hash() -> str:
    """Hash of brdffit's fitting and model sources: a code change invalidates the exports."""
    if "source" not in _STATE:
        _STATE["source"] = sources_hash(Path(__file__).resolve().parents[1])
    return _STATE["source"]


def sources_hash(root: Path) -> str:
    """Hash of the paths and contents of every ``.py`` file below ``root/fitting`` and
    ``root/models``, subfolders too: a file moved or added there may shape a compiled program."""
    import hashlib

    h = hashlib.sha256()
    for sub in ("fitting", "models"):
        for f in sorted((root / sub).rglob("*.py")):
            h.update(f.relative_to(root).as_posix().encode())
            h.update(f.read_bytes())
    return h.hexdigest()[:16]


def _key_text(key, example) -> str | None:
    import jax

    parts = []
    for k in key:
        if hasattr(k, "param_names") and hasattr(k, "formula"):
            if not _library_model(k):
                return None
            parts.append(f"model={k.name}/{k.channels}/{k.param_names}")
        elif isinstance(k, (str, int, float, bool)) or k is None:
            parts.append(repr(k))
        else:
            return None
    shapes = [(tuple(a.shape), str(a.dtype)) for a in jax.tree_util.tree_leaves(example)]
    return f"{parts}|{shapes}|{jax.tree_util.tree_structure(example)}|jax {jax.__version__}|{_source_hash()}"


def _cpu_features() -> str:
    """The CPU's instruction-set flags (Linux's /proc/cpuinfo), or ``platform.processor()`` elsewhere."""
    if "features" not in _STATE:
        import platform

        features = None
        try:
            with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
                features = next((line for line in fh if line.startswith(("flags", "Features"))), None)
        except OSError:
            pass
        if features is None:  # not Linux: platform.processor() (it runs `uname -p`, ~6 ms, on Linux)
            features = platform.processor()
        _STATE["features"] = features.strip()
    return _STATE["features"]


def _machine() -> str:
    """What a compiled CPU program depends on besides its source and shapes: jaxlib, the backend,
    and the instruction set it was compiled for (a cache folder shared between machines must not
    hand a program built for AVX-512 to a CPU without it)."""
    if "machine" not in _STATE:
        import platform

        import jax
        import jaxlib

        device = jax.devices()[0]
        _STATE["machine"] = (f"jaxlib {jaxlib.__version__}|{device.platform}|{device.client.platform_version}|"
                             f"{platform.machine()}|{_cpu_features()}")
    return _STATE["machine"]


def compiler_options() -> dict:
    """XLA options of brdffit's compiled fit programs: on a CPU with AVX-512, vectors of 512 bits
    (``xla_cpu_prefer_vector_width``; XLA's default, 256, leaves half of each register unused). Measured
    on the project's machine (Intel, AVX-512): ggx's normal equations on UBO-81 0.47 -> 0.41 ms, a
    64 x 64 ggx BTF's fit on one core 548-579 -> 599-616 texels/s
    (benchmarks/README.md), equal to rounding (2e-11 relative at most on the shared files' fits). Where the
    CPU has no AVX-512 nothing is set (the option would be moot), nor where ``XLA_FLAGS`` sets the width."""
    if "options" not in _STATE:
        import jax

        wide = (jax.devices()[0].platform == "cpu" and "avx512f" in _cpu_features().split()
                and "xla_cpu_prefer_vector_width" not in os.environ.get("XLA_FLAGS", ""))
        _STATE["options"] = {"xla_cpu_prefer_vector_width": 512} if wide else {}
    return dict(_STATE["options"])


def _program_file(key, example) -> tuple[str, Path] | None:
    """(key text, file) of the program of ``key`` for ``example``'s shapes on disk, or None: no disk cache,
    several processes (a loaded program would be bound to every process's devices; JAX's own cache serves
    them), or a key of no kept kind (a model that is not the library's)."""
    import hashlib

    import jax

    path = _STATE["dir"]
    text = _key_text(key, example) if path is not None and jax.process_count() == 1 else None
    if text is None:
        return None
    # XLA_FLAGS changes what XLA compiles (JAX's own cache key holds them as well).
    flags = os.environ.get("XLA_FLAGS", "").strip()
    text = f"{text}|{_machine()}|XLA_FLAGS={flags}|{sorted(compiler_options().items())}"
    return text, path / "brdffit-programs" / (hashlib.sha256(text.encode()).hexdigest()[:32] + ".bin")


def _wrap(compiled_flat):
    """The callable of a kept program: it takes the original arguments, the program their flat list (and
    returns its outputs and the salt, see :func:`load_or_compile`)."""
    import jax

    return lambda *args: compiled_flat(*jax.tree_util.tree_leaves(args))[0]


def _load(text: str, file: Path):
    """The program kept in ``file`` under ``text``, loaded, or None (absent, damaged, or another key's)."""
    import pickle

    from jax.experimental import serialize_executable

    try:
        saved = pickle.loads(file.read_bytes())
        if saved["key"] != text:  # a hash collision or a file of another version
            return None
        if saved["lapack"]:
            # LAPACK's entry points are looked up (from SciPy) when a program calling them is lowered; a
            # loaded program is not lowered, so look them up here (without them it would call a null pointer).
            from jax._src.lax.linalg import initialize_lapack  # jax is pinned (pyproject)

            initialize_lapack()
        program = _wrap(serialize_executable.deserialize_and_load(saved["program"], saved["in_tree"],
                                                                  saved["out_tree"]))
    except Exception:  # noqa: BLE001 - a damaged or foreign file: compiled again by the caller
        return None
    try:  # used now: the last to be pruned (_prune)
        os.utime(file)
    except OSError:
        pass
    return program


def load_or_compile(key, build, example):
    """Compiled ``jax.jit(build())`` for ``example``'s shapes; with the cache on, the compiled
    program itself is kept on disk, so that a second process neither traces, lowers nor compiles
    it: it only loads the machine code (``jax.experimental.serialize_executable``; loading runs
    what the file holds, so the cache folder is trusted as JAX's own cache folder is).

    Keeping the traced program instead (``jax.export``) lowered it again in every process (which also
    imported scipy.linalg for LAPACK) before JAX's cache handed its machine code back: a second
    process's fit was markedly slower (``benchmarks/bench_cli.py`` prints the phases; results in
    benchmarks/README.md)."""
    import hashlib
    import pickle
    import secrets

    import jax
    import jax.numpy as jnp

    options = compiler_options()
    where = _program_file(key, example)
    if where is None:
        return jax.jit(build()).lower(*example).compile(compiler_options=options)
    text, file = where
    # The program takes the flat list of arrays (our own pytree types, such as problem.Data, are not
    # kept on disk); the returned callable takes the original arguments.
    leaves, treedef = jax.tree_util.tree_flatten(example)
    program = _load(text, file)
    if program is not None:
        return program
    from jax.experimental import serialize_executable

    fn = build()
    _listen_for_jax_hits()  # here, its only reader: also when the folder was set without enable()

    def compile_salted(salt: int):
        """Compiled program returning (outputs, salt); and whether JAX's own cache handed it back."""
        hits = _STATE["jax_hits"]
        compiled = jax.jit(lambda *flat: (fn(*jax.tree_util.tree_unflatten(treedef, flat)), jnp.int32(salt))
                           ).lower(*leaves).compile(compiler_options=options)
        return compiled, _STATE["jax_hits"] != hits

    # A program that JAX's own cache hands back runs, but serialised again it lacks its machine code
    # ("Function ... not found" in the next process; seen with jaxlib 0.10), so only a program
    # compiled here may be kept. The salt, our key's hash as an extra output, makes the program's
    # HLO (JAX's key) ours alone: a source change that leaves the HLO as it was (a comment, a
    # release) is not answered from JAX's cache. Should it be all the same (our file deleted, JAX's
    # entry kept), compile once more under a fresh salt rather than stay on the slow path for good.
    compiled, from_jax = compile_salted(int(hashlib.sha256(text.encode()).hexdigest()[:7], 16))
    if from_jax:
        compiled, from_jax = compile_salted(secrets.randbits(28))
        if from_jax:
            return _wrap(compiled)
    try:
        program, in_tree, out_tree = serialize_executable.serialize(compiled)
        # Any custom call: make sure LAPACK's entry points are set before a later process runs it
        # (the fit programs call none: see linalg.py).
        data = pickle.dumps({"key": text, "program": program, "in_tree": in_tree, "out_tree": out_tree,
                             "lapack": "custom_call_target" in compiled.as_text()})
    except Exception:  # noqa: BLE001 - not serialisable: no disk copy
        return _wrap(compiled)
    tmp = file.with_suffix(f".tmp{os.getpid()}")
    try:
        file.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_bytes(data)
        os.replace(tmp, file)  # atomic: concurrent processes write equivalent programs
    except OSError:  # a full disk or a read-only folder: no disk copy, no partial file
        tmp.unlink(missing_ok=True)
    else:
        _prune(file.parent, keep=file)
    return _wrap(compiled)


#: compiled programs of this process, by (key, argument shapes), the most recently used last
_CACHE: collections.OrderedDict = collections.OrderedDict()
#: Most programs kept loaded at once. A loaded XLA CPU program holds about 300 memory mappings of its
#: own (measured: 200 programs, 63 000 mappings), and Linux allows a process 65 530
#: (vm.max_map_count): past about 210 programs the next load segfaulted inside XLA (a test worker
#: of the suite, late in the run). The least recently used program is let go beyond this (its
#: mappings with it); it comes back from the disk cache in a fraction of a second.
MAX_LOADED = 64


def _shape_key(tree):
    import jax

    return tuple((a.shape, str(a.dtype)) for a in jax.tree_util.tree_leaves(tree))


def compiled(key, build: Callable[[], Callable], *example, note: Callable[[str], None] | None = None) -> tuple[Any, float]:
    """Compile ``build()`` for these argument shapes once per process and, through the disk cache,
    once per machine; returns (compiled function, compile seconds this call).

    On disk (:func:`load_or_compile`): the compiled program itself, so that a second process
    neither traces (nor imports optimistix), lowers nor compiles it. Loaded already when a run of its
    kind loads its programs ahead (:func:`ahead`)."""
    full = (key, _shape_key(example))
    hit = _CACHE.get(full)
    where = _program_file(key, example) if hit is None or _USED else None
    for used in _USED:
        if where is not None and where[0] not in used:
            used[where[0]] = where[1].name
    if hit is not None:
        _CACHE.move_to_end(full)
        return hit, 0.0
    if note is not None:
        note(f"compiling: {key[0]} ({'cached on disk' if cache_enabled() else 'no disk cache'})")
    t0 = time.perf_counter()
    loading = _AHEAD.pop(where[0], None) if where is not None else None
    # Being loaded: wait for it; not reached yet (cancelled): loaded here now, not after the others.
    fn = loading.result() if loading is not None and not loading.cancel() else None
    if fn is None:
        fn = load_or_compile(key, build, example)
    dt = time.perf_counter() - t0
    _CACHE[full] = fn
    if where is not None:
        _TEXTS[where[0]] = full
    while len(_CACHE) > MAX_LOADED:
        _CACHE.popitem(last=False)
    return fn, dt


# -- programs loaded ahead ------------------------------------------------------------------------------
#: Programs being loaded ahead (:func:`ahead`), by key text: futures of the loaded programs (None: not loaded).
_AHEAD: dict = {}
#: The programs each :func:`ahead` block open now has used, by key text: their files' names, in order of use.
_USED: list[dict] = []
#: The key in ``_CACHE`` of each program loaded or compiled here, by key text (programs let go stay listed).
_TEXTS: dict = {}


@contextlib.contextmanager
def ahead(kind: str):
    """Within the block, the programs that the last run of this ``kind`` used are loaded from the disk cache
    in a thread, in the order it used them, so that loading them overlaps what the run does first (a BTF's
    first tiles are read meanwhile; loading a program is ~0.05-0.2 s, most of it in XLA); at the end
    the programs this run used are kept as the kind's, in ``brdffit-programs/ahead-<hash>.json``. A
    program the run asks for before its turn came is loaded as without this; one loaded and not asked for
    is let go at the end. With the disk cache off: nothing."""
    import hashlib
    import json

    path = _STATE["dir"]
    if path is None:
        yield
        return
    record = path / "brdffit-programs" / f"ahead-{hashlib.sha256(kind.encode()).hexdigest()[:16]}.json"
    try:
        last = json.loads(record.read_text())
    except (OSError, ValueError):
        last = {}
    last = last if isinstance(last, dict) else {}
    mine = {}
    for text in last:
        if text not in _AHEAD and _TEXTS.get(text) not in _CACHE:  # not loading, nor loaded in this process
            mine[text] = _AHEAD[text] = concurrent.futures.Future()

    def load():
        for text, future in mine.items():
            if future.set_running_or_notify_cancel():
                future.set_result(_load(text, record.parent / Path(str(last[text])).name))

    if mine:
        threading.Thread(target=load, name="brdffit-programs-ahead", daemon=True).start()
    used: dict = {}
    _USED.append(used)
    try:
        yield
    finally:
        _USED.remove(used)
        for text, future in mine.items():
            if _AHEAD.get(text) is future:
                del _AHEAD[text]
                future.cancel()  # not started: not loaded; else loaded and let go
        if used and used != last:
            tmp = record.with_suffix(f".tmp{os.getpid()}")
            try:
                tmp.write_text(json.dumps(used))
                os.replace(tmp, record)
            except OSError:  # a read-only folder: nothing kept
                tmp.unlink(missing_ok=True)
