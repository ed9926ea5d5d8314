"""``brdffit.fit_btf_database``: every BTF of a folder fitted, each into ``OUT/<name>/`` (docs/btf.md#btfs-per-texel-fitting
"At scale"; ``brdffit fit-btf DIR`` when DIR holds several BTFs).

A database folder holds BTFs as entries of its own: image folders (the layouts ``load_btf``
reads) and ``.zip`` archives of them; hidden entries and other files are ignored, and ``<name>`` is
the folder's name or the archive's stem (two entries of one name are refused). A folder that
holds a BTF's images itself (or its ``tvTTT_pvPPP`` view folders) is one BTF, not a database.

Before any fitting every BTF's image set is checked and its first image read (its texel count
for the progress bar): a broken entry is reported (one line naming the file, exit 2) before any
work. Then one material after another: read (:func:`load_btf`), fitted (the run of
:func:`brdffit.fit_btf`: resumable tiles, a Dask cluster when ``client`` is given), its results
written to ``OUT/<name>/`` (``params.exr``, previews, ``summary.json``). One progress bar counts
every texel left to fit, with the time left. Finally ``OUT/summary.csv`` and ``OUT/summary.json``
hold one row per material: texels, texels per second (of the run that finished it), median loss,
converged share.

Resuming across materials. ``OUT/database.json`` records the model and options: a run that finds
the same record skips every material whose ``OUT/<name>/params.exr`` exists (finished) and resumes
the unfinished one from its tiles; another record is an error unless ``force`` (which fits every
material again). An interrupted run (Ctrl-C included: a finished material is a complete result
and stays) is resumed by running it again. ``OUT/.lock`` refuses a second run writing the same
folder at once.

The BTF caches (``cache_dir``, or a temporary folder when None) are removed as soon as their
material is finished: a database does not fit on most disks as float32 caches.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import json
import sys
from pathlib import Path

from .._files import atomic_file, complete_with
from .._progress import progress_bar
from ..errors import InputError, UsageError
from ..io.images import IMAGE_EXTENSIONS, VIEW_DIR
from . import run as _run
from .fit import fit_options, open_run, tile_job
from .reader import btf_shape, load_btf

RECORD = "database.json"
COLUMNS = ("material", "texels", "texels_per_second", "median_loss", "converged_share", "converged", "status")


@dataclasses.dataclass(frozen=True)
class Material:
    """One BTF of a database: its name (the output folder's), source and texel count."""

    name: str
    source: Path
    texels: int


def is_database(folder) -> bool:
    """True when ``folder`` holds BTFs as entries (folders or zips), not the images of one BTF."""
    folder = Path(folder)
    if not folder.is_dir():
        return False
    entries = [e for e in folder.iterdir() if not e.name.startswith(".")]
    if any(e.is_file() and e.suffix.lower() in IMAGE_EXTENSIONS for e in entries):
        return False
    if any(e.is_dir() and VIEW_DIR.match(e.name) for e in entries):
        return False
    return any(e.is_dir() or e.suffix.lower() == ".zip" for e in entries)


def materials(folder, *, region=None, step: int = 1, srgb: bool = True) -> list[Material]:
    """The BTFs of the database ``folder``, in name order, each checked (an InputError names the
    first broken one)."""
    folder = Path(folder)
    if not is_database(folder):
        raise InputError(folder, "not a folder of BTFs (image folders or .zip archives of them)")
    found: dict[str, Path] = {}
    for entry in sorted(folder.iterdir()):
        if entry.name.startswith(".") or not (entry.is_dir() or entry.suffix.lower() == ".zip"):
            continue
        name = entry.stem if entry.is_file() else entry.name
        if name in found:
            raise InputError(folder, f"two BTFs named {name!r}: {found[name].name} and {entry.name} (rename one)")
        found[name] = entry
    out = []
    for name, source in found.items():
        h, w, _ = btf_shape(source, region=region, step=step, srgb=srgb)
        out.append(Material(name, source, h * w))
    return out


@dataclasses.dataclass(frozen=True)
class DatabaseFit:
    """The result of :func:`fit_btf_database`: one row per material (``COLUMNS``) and the folder."""

    out: Path
    rows: tuple

    @property
    def not_converged(self) -> int:
        """Texels that did not converge, over every material."""
        return sum(r["texels"] - r["converged"] for r in self.rows)

    def table(self) -> str:
        """The rows as aligned text."""
        head = ("material", "texels", "texels/s", "median loss", "converged")
        body = [(r["material"], str(r["texels"]), "-" if r["texels_per_second"] is None else f"{r['texels_per_second']:.1f}",
                 "-" if r["median_loss"] is None else f"{r['median_loss']:.4g}", f"{100 * r['converged_share']:.1f} %")
                for r in self.rows]
        widths = [max(len(x[i]) for x in [head, *body]) for i in range(len(head))]
        lines = ["  ".join(c.ljust(wd) if i == 0 else c.rjust(wd) for i, (c, wd) in enumerate(zip(x, widths)))
                 for x in [head, *body]]
        return "\n".join(lines)

    def __repr__(self) -> str:
        return f"DatabaseFit({len(self.rows)} materials in {self.out})\n{self.table()}"


def fit_btf_database(
    folder,
    model,
    *,
    out,
    loss: str = "log",
    solver: str | None = None,
    force: bool = False,
    progress: bool | None = None,
    client=None,
    processes: int | None = None,
    neighbours: bool = True,
    region=None,
    step: int = 1,
    includes_cos: bool = False,
    scale: float = 1.0,
    srgb: bool = True,
    tile: int = 16,
    cache_dir=None,
    **batch_options,
) -> DatabaseFit:
    """Fit ``model`` to every texel of every BTF in ``folder``; see the module docstring.

    ``region``, ``step``, ``includes_cos``, ``scale``, ``srgb``, ``tile``, ``cache_dir``: as for
    :func:`brdffit.load_btf` (for every material); the others as for :func:`brdffit.fit_btf`.
    """
    import jax

    from ..fitting.problem import resolve_model

    if jax.process_count() > 1:
        raise UsageError("fit_btf_database runs in one process; for a cluster give it client= (Dask)")
    _, given = fit_options(loss, solver, batch_options)  # checked before any work
    read = {"region": None if region is None else list(region), "step": int(step), "includes_cos": bool(includes_cos),
            "scale": float(scale), "srgb": bool(srgb), "tile": int(tile)}
    record = json.loads(json.dumps({"model": resolve_model(model, 3).name, "loss": loss, "neighbours": bool(neighbours),
                                    "options": {k: str(v) for k, v in sorted(given.items())}, "read": read}))
    mats = materials(folder, region=region, step=step, srgb=srgb)
    out = Path(out)
    with _database_folder(out, record, force):
        left = [m for m in mats if force or not (out / m.name / "params.exr").is_file()]
        shown = sys.stderr.isatty() if progress is None else bool(progress)
        with progress_bar(f"{record['model']} on {Path(folder).name}", sum(m.texels for m in left), shown=shown,
                          rate="texels") as bar:
            plan = _Plan(out, model, loss, solver, neighbours, read, cache_dir, client, processes, force, batch_options)
            for i, m in enumerate(left, 1):
                # A material is a complete result once its params.exr (written last) is committed: an
                # interrupt from that moment on keeps it (the CLI's Ctrl-C removes only what this
                # command committed since its last complete result).
                complete_with(out / m.name / "params.exr")
                plan.fit(m, f"{m.name} ({i}/{len(left)})", bar)
        result = DatabaseFit(out, tuple(_row(out / m.name, m, m in left) for m in mats))
        _write_summary(result)
    return result


@dataclasses.dataclass(frozen=True)
class _Plan:
    """How every material of a run is read and fitted, and where to."""

    out: Path
    model: object
    loss: str
    solver: str | None
    neighbours: bool
    read: dict
    cache_dir: object
    client: object
    processes: int | None
    force: bool
    options: dict

    def fit(self, m: Material, where: str, bar) -> None:
        """Read, fit and write material ``m``; its BTF (and a temporary cache) goes when this
        returns, its cache in ``cache_dir`` once its maps are written."""
        bar.describe(f"reading {where}")
        btf = load_btf(m.source, **self.read, cache_dir=self.cache_dir, name=m.name)
        job = tile_job(btf, self.model, self.loss, self.solver, self.neighbours, **self.options)
        with open_run(btf, job, out=self.out / m.name, force=self.force, client=self.client,
                      processes=self.processes) as run:
            bar.skip(run.texels(run.results))
            bar.describe(f"{job.model.name} on {where}")
            run.fit(bar)
        if self.cache_dir is not None:
            _remove_cache(btf)


def _row(folder: Path, m: Material, fitted_now: bool) -> dict:
    try:
        s = json.loads((folder / "summary.json").read_text())
    except (OSError, ValueError):
        raise InputError(folder / "summary.json", "missing or unreadable; fit this material again (--force)") from None
    return {"material": m.name, "texels": int(s["texels"]), "texels_per_second": s.get("texels_per_second"),
            "median_loss": s["loss_value"].get("median"), "converged_share": s["converged"] / max(s["texels"], 1),
            "converged": int(s["converged"]),
            "status": "fitted" if fitted_now else "done before"}


def _write_summary(result: DatabaseFit) -> None:
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(result.rows)
    with atomic_file(result.out / "summary.csv", force=True) as tmp:
        tmp.write_text(text.getvalue())
    with atomic_file(result.out / "summary.json", force=True) as tmp:
        tmp.write_text(json.dumps({"materials": list(result.rows)}, indent=2) + "\n")


def _remove_cache(btf) -> None:
    """The BTF's cache file and its record (``load_btf``'s, in ``cache_dir``)."""
    for f in (btf.cache, btf.cache.with_suffix(".json")):
        with contextlib.suppress(FileNotFoundError):
            f.unlink()


@contextlib.contextmanager
def _database_folder(out: Path, record: dict, force: bool):
    """``out`` locked for this run, checked against ``record`` (``OUT/database.json``), which is
    written when absent or replaced with ``force``."""
    if out.exists() and not out.is_dir():
        raise UsageError(f"{out}: is a file; the output of a database run is a folder")
    out.mkdir(parents=True, exist_ok=True)
    held = _run.lock(out, "fit-btf database run")
    try:
        try:
            previous = json.loads((out / RECORD).read_text())
        except FileNotFoundError:
            previous = None
        except (OSError, ValueError):
            previous = {}
        if not force:
            if previous is None and any(e.name != ".lock" for e in out.iterdir()):
                raise UsageError(f"{out}: exists and is not a fit-btf database run (use --force to write there)")
            if previous is not None and previous != record:
                raise UsageError(f"{out}: holds a database run of another model or options "
                                 "(use --force to fit every material again)")
        if previous != record:
            complete_with(out / RECORD)  # the record stays with the materials an interrupted run keeps
            with atomic_file(out / RECORD, force=True) as tmp:
                tmp.write_text(json.dumps(record, indent=2) + "\n")
        yield
    finally:
        held.close()
