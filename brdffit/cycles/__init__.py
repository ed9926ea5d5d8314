"""Blender's Cycles, driven in a worker process (docs/materials.md#native-materials-and-exports): the second renderer and the ``.blend`` export.

Blender runs as ``bpy`` 5.0.1 (Blender as a Python module), which needs numpy < 2 while jax needs
numpy >= 2, so it lives in an environment of its own and brdffit never imports it. The worker
(``brdffit/cycles/_worker.py``, run by that environment's interpreter) reads one JSON request per
line on its stdin and answers one JSON line; images come back as ``.npy`` files in a folder the
request names (see the worker's docstring for the protocol). One worker serves every request of a
process (:func:`worker`): starting Blender costs about a second, a small render a few milliseconds.

The interpreter: ``$BRDFFIT_BLENDER_PYTHON``, else ``.venv-blender/bin/python`` in the project
folder, the folder that holds the ``brdffit`` package of this installation (a checkout, where
``make test`` / ``scripts/setup_blender.sh`` create it). Without either, every Blender path raises
:class:`brdffit.errors.UsageError` with one line saying so (the CLI's exit 2).
"""

from __future__ import annotations

import atexit
import json
import os
import queue
import shutil
import subprocess
import tempfile
import threading
from pathlib import Path

import numpy as np

from .._files import forget_process, remove_scratch, scratch_dir, start_process
from ..errors import UsageError

WORKER_SCRIPT = Path(__file__).with_name("_worker.py")
ENV_VAR = "BRDFFIT_BLENDER_PYTHON"
#: Seconds to wait for Blender to start (importing bpy takes about 1 s; a cold disk more).
START_TIMEOUT = 120.0


def project_root() -> Path:
    """The folder holding the ``brdffit`` package (a checkout, or an editable install's source)."""
    return Path(__file__).resolve().parent.parent.parent


def blender_python() -> Path:
    """The interpreter that runs the worker, or one UsageError line saying how to get one."""
    env = os.environ.get(ENV_VAR)
    if env:
        path = Path(env)
        if not (path.is_file() and os.access(path, os.X_OK)):
            raise UsageError(f"{ENV_VAR}={env}: no such Python interpreter (it should be a Python with "
                             "bpy 5.0, e.g. .venv-blender/bin/python)")
        return path
    path = project_root() / ".venv-blender" / "bin" / "python"
    if not path.exists():
        raise UsageError(f"Blender is not set up: no {path} (run `make setup-blender` or "
                         f"scripts/setup_blender.sh in {project_root()}, or set {ENV_VAR} to a Python with bpy 5.0)")
    return path


def available() -> str | None:
    """None when a Blender interpreter is there, else the one line :func:`blender_python` would raise."""
    try:
        blender_python()
    except UsageError as exc:
        return str(exc)
    return None


class BlenderError(UsageError, RuntimeError):
    """The worker refused or failed a request, ended, or did not answer in time; ``str()`` is its
    one line. Not a bug of brdffit: the CLI reports it as it reports a missing Blender (exit 2)."""

    def __init__(self, problem: str):
        super().__init__(problem)


#: The most seconds a request may take before the worker counts as hung (it is then stopped and the
#: request fails with one line): a fixed allowance (Blender's first use of a scene type) plus the
#: request's work, each about 100 to 300 times what it takes on one CPU core (measured: a .blend
#: 0.23 s, 81 gonio pairs 0.3 s, a 64 x 64 sphere at 16 spp 0.06 s per light).
BUDGET_S = 60.0
BUDGET_PER_PAIR_S = 1.0
BUDGET_PER_SAMPLE_S = 1e-4


def budget(op: str, args: dict) -> float:
    """Seconds a request ``op`` with ``args`` may take (see ``BUDGET_S``)."""
    if op == "gonio":
        return BUDGET_S + BUDGET_PER_PAIR_S * len(args.get("pairs", ()))
    if op == "sphere":
        size = int(args.get("size", 1))
        return BUDGET_S + BUDGET_PER_SAMPLE_S * len(args.get("lights", ())) * size * size * int(args.get("spp", 1))
    if op == "render_file":  # the file's own resolution: a .blend export's is 512 x 512; allow 1024 x 1024
        return BUDGET_S + BUDGET_PER_SAMPLE_S * 1024 * 1024 * int(args.get("spp", 1))
    if op == "blend_maps":  # images written and packed: per texel and texture, as a sample
        return BUDGET_S + BUDGET_PER_SAMPLE_S * int(args.get("width", 1)) * int(args.get("height", 1)) * \
            max(1, len(args.get("textures", ())))
    return BUDGET_S


_ENDED = object()  # what Worker._receive returns once the worker's output has ended


class Worker:
    """One Blender process answering requests (see the module docstring). It runs in a session of
    its own with its own temporary folder (``scratch``: Blender's ``blender_*`` folder and every
    request's output folder live in it), both stopped and removed by :meth:`close`, and by the
    ``brdffit`` executable's Ctrl-C at any moment (``brdffit._files``)."""

    def __init__(self, python: str | os.PathLike | None = None, start_timeout: float = START_TIMEOUT):
        self.python = Path(python) if python is not None else blender_python()
        self._log = tempfile.TemporaryFile(mode="w+b")  # Blender's own output; its tail in errors
        self.scratch = scratch_dir("brdffit-blender-")
        env = dict(os.environ)
        env.pop("PYTHONPATH", None)  # the worker's interpreter has its own packages (numpy 1.x)
        env["PYTHONNOUSERSITE"] = "1"
        env["TMPDIR"] = str(self.scratch)  # Blender's own temporary folder goes in there
        self._proc = None
        try:
            self._proc = start_process([str(self.python), "-u", str(WORKER_SCRIPT)], stdin=subprocess.PIPE,
                                       stdout=subprocess.PIPE, stderr=self._log, env=env)
        except OSError as exc:
            self.close()
            raise UsageError(f"{self.python}: cannot start the Blender worker: {exc.strerror or exc}") from None
        self._lines: queue.Queue = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()
        self._next_id = 0
        self._lock = threading.Lock()
        try:
            hello = self._receive(start_timeout)
        except BaseException:
            self.close()
            raise
        if hello is None or hello is _ENDED or not hello.get("ready"):
            why = self.log_tail() or "no output"
            self.close()
            raise UsageError(f"{self.python}: the Blender worker did not start ({why})")
        self.blender = hello.get("blender")

    def _read(self):
        for raw in self._proc.stdout:
            self._lines.put(raw)
        self._lines.put(None)  # the worker ended

    def _receive(self, timeout: float | None) -> dict | None:
        """The next reply; None when none came within ``timeout``, ``_ENDED`` when the worker's
        output ended (it may not be reaped yet: ``alive`` cannot tell these apart)."""
        try:
            raw = self._lines.get(timeout=timeout)
        except queue.Empty:
            return None
        if raw is None:
            return _ENDED
        try:
            answer = json.loads(raw)
        except ValueError:
            answer = None
        if not isinstance(answer, dict):
            raise BlenderError(f"the Blender worker answered something else than a reply: {raw[:80]!r}")
        return answer

    def log_tail(self, n: int = 1) -> str:
        """The last n non-empty lines Blender wrote (stderr), for error messages."""
        self._log.seek(0)
        lines = [ln.strip() for ln in self._log.read().decode(errors="replace").splitlines() if ln.strip()]
        return " | ".join(lines[-n:])

    @property
    def alive(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    def call(self, op: str, args: dict, out: str | os.PathLike | None = None, timeout: float | None = None) -> dict:
        """Send one request and wait for its reply's result, at most ``timeout`` seconds (default:
        :func:`budget`); BlenderError if the worker refuses it, dies or does not answer in time (it
        is then stopped: a worker interrupted in a request is never asked again)."""
        timeout = budget(op, args) if timeout is None else timeout
        with self._lock:
            if not self.alive:
                raise BlenderError(f"the Blender worker has ended ({self.log_tail() or 'no output'})")
            self._next_id += 1
            request = {"id": self._next_id, "op": op, "args": args, "out": None if out is None else str(out)}
            try:
                self._proc.stdin.write((json.dumps(request) + "\n").encode())
                self._proc.stdin.flush()
                answer = self._receive(timeout)
            except (BrokenPipeError, OSError):
                self._stop()
                raise BlenderError(f"the Blender worker has ended ({self.log_tail() or 'no output'})") from None
            except BaseException:  # a Ctrl-C while it works: its state is unknown
                self._stop()
                raise
            if answer is None or answer is _ENDED:
                self._stop()
                if answer is None:
                    raise BlenderError(f"the Blender worker did not answer {op!r} within {timeout:g} s (stopped)")
                raise BlenderError(f"the Blender worker ended during {op!r} ({self.log_tail() or 'no output'})")
            if answer.get("id") != request["id"]:
                self._stop()
                raise BlenderError(f"the Blender worker answered request {answer.get('id')} to {request['id']}")
            if not answer.get("ok"):
                raise BlenderError(f"Blender: {answer.get('error')}")
            return answer.get("result", {})

    def _stop(self):
        if self.alive:
            self._proc.kill()
            self._proc.wait()

    def close(self):
        if self._proc is not None:
            if self._proc.poll() is None:
                try:
                    self._proc.stdin.close()  # end of input: the worker's loop ends
                    self._proc.wait(timeout=10)
                except (OSError, subprocess.TimeoutExpired):
                    self._stop()
            forget_process(self._proc)
        remove_scratch(self.scratch)
        self._log.close()


_SHARED: Worker | None = None
_SHARED_LOCK = threading.Lock()


def worker() -> Worker:
    """The process's shared worker, started on first use (again if it has ended)."""
    global _SHARED
    with _SHARED_LOCK:
        if _SHARED is None or not _SHARED.alive:
            if _SHARED is not None:
                _SHARED.close()  # an ended worker's folder goes with it
            _SHARED = Worker()
        return _SHARED


@atexit.register
def _close_shared():
    if _SHARED is not None:
        _SHARED.close()


def request(op: str, args: dict, timeout: float | None = None) -> tuple[dict, Path]:
    """Run one request on the shared worker with a fresh output folder (in the worker's scratch
    folder); returns (result, folder). The caller removes the folder (:func:`_load` does).
    ``timeout``: see :meth:`Worker.call`."""
    w = worker()
    out = Path(tempfile.mkdtemp(prefix="request-", dir=w.scratch))
    try:
        return w.call(op, args, out, timeout=timeout), out
    except BaseException:
        shutil.rmtree(out, ignore_errors=True)
        raise


def _load(op: str, args: dict, key: str, timeout: float | None = None) -> np.ndarray:
    result, out = request(op, args, timeout)
    try:
        return np.load(out / result[key])
    finally:
        shutil.rmtree(out, ignore_errors=True)


def _dirs(a, name: str) -> np.ndarray:
    a = np.asarray(a, np.float64).reshape(-1, 3)
    if not np.all(np.isfinite(a)):
        raise UsageError(f"{name}: directions must be finite")
    return a


def _material(material) -> dict:
    """Request arguments naming a material: a native dict, or (path to a .blend file, material name)."""
    if isinstance(material, dict):
        return {"material": material}
    path, name = material
    return {"blend": [str(Path(path).resolve()), str(name)]}


def gonio(material, wi, wo, irradiance: float = 1.0) -> np.ndarray:
    """Cycles measured as a gonioreflectometer: (N, 3) radiance f(wi, wo) (n.wi) E of a large plane
    (normal +z) with ``material`` (a ``blender:principled`` native dict, or a (.blend path, material
    name) pair) under a sun of angle 0 towards wi, seen by an orthographic camera from wo. NaN where
    wi or wo is below the horizon."""
    wi, wo = _dirs(wi, "wi"), _dirs(wo, "wo")
    if wi.shape != wo.shape:
        raise UsageError(f"wi and wo differ in shape: {wi.shape} and {wo.shape}")
    pairs = np.stack([wi, wo], 1).tolist()
    return _load("gonio", {**_material(material), "pairs": pairs, "irradiance": float(irradiance)}, "values")


def render_sphere(material, lights, size: int = 256, irradiance: float = 1.0, spp: int = 4,
                  seed: int = 0) -> np.ndarray:
    """(L, size, size, 3) linear radiance of the unit sphere with ``material`` (as :func:`gonio`) in
    Cycles, one image per light (unit world directions towards the lights), docs/validation.md#validation-rendering framing; not masked."""
    args = {**_material(material), "lights": _dirs(lights, "lights").tolist(), "size": int(size),
            "irradiance": float(irradiance), "spp": int(spp), "seed": int(seed)}
    return _load("sphere", args, "images")


def blend_file(material: dict, name: str, extras: dict) -> bytes:
    """The bytes of a .blend file holding a UV sphere with ``material`` (extras: a custom property)."""
    result, out = request("blend", {"material": material, "name": name, "extras": extras})
    try:
        return (out / result["blend"]).read_bytes()
    finally:
        shutil.rmtree(out, ignore_errors=True)


def blend_maps_file(material: dict, textures: dict, name: str, extras: dict, width: int, height: int) -> bytes:
    """The bytes of a .blend file holding a square of width x height texels with ``material``, whose
    inputs in ``textures`` ({socket: {"path", "name", "data", "scalar"}}: image files that Blender packs
    into the file) are image textures (the worker's ``blend_maps``)."""
    args = {"material": material, "textures": textures, "name": name, "extras": extras,
            "width": int(width), "height": int(height)}
    result, out = request("blend_maps", args)
    try:
        return (out / result["blend"]).read_bytes()
    finally:
        shutil.rmtree(out, ignore_errors=True)


def render_file(path: str | os.PathLike, light, irradiance: float = 1.0, spp: int = 4) -> np.ndarray:
    """(H, W, 3) linear radiance of a .blend file rendered by Cycles through its own camera, direct
    light only, its one sun turned towards ``light`` (a unit world direction) with ``irradiance``."""
    args = {"path": str(Path(path).resolve()), "light": _dirs(light, "light")[0].tolist(),
            "irradiance": float(irradiance), "spp": int(spp)}
    return _load("render_file", args, "image")


def inspect(path: str | os.PathLike) -> dict:
    """The Principled BSDF materials Blender reads from a .blend file, or imports from a glTF file with
    its own importer: {name: {"distribution", "inputs", "properties", "users"}}."""
    result, out = request("inspect", {"path": str(Path(path).resolve())})
    shutil.rmtree(out, ignore_errors=True)
    return result["materials"]
