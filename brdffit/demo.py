"""``brdffit demo``: the pipeline on the bundled sample measurement (docs/cli.md#the-command-line-and-set-up).

Load the sample (``data/sample_ubo81.exr``, or a fresh generation when the package is installed
without the repository's ``data/``), show what it holds, convert it to NPZ, plot the 81 x 81
table, fit the generating model from defaults, compare models and solvers (error against run
time), and validate the fit by rendering it beside the measured table in Mitsuba. Everything is
written into a temporary folder that replaces ``out`` only when all steps succeeded (atomic,
``force`` to replace).
"""

from __future__ import annotations

import dataclasses

from pathlib import Path

import numpy as np

from .measurement import Measurement


def sample_measurement() -> tuple[Measurement, str]:
    """The bundled sample and where it came from."""
    from . import sample
    from .io import load

    if sample.DEFAULT_PATH.exists():
        return load(sample.DEFAULT_PATH), str(sample.DEFAULT_PATH)
    return sample.generate(), "brdffit.sample.generate()"


DEMO_MODELS = ("lambert", "blinn_phong", "ggx", "lambert+ggx+ggx")
DEMO_SOLVERS = ("lm", "scipy")


@dataclasses.dataclass(frozen=True)
class DemoResult:
    files: dict[str, Path]  # written files by role
    converged: bool  # did the demo's fit converge (the CLI exits 1 when not)


def run_demo(out: str | Path, force: bool = False, console=None, size: int = 128) -> DemoResult:
    """The whole pipeline on the sample, into ``out``: load + info, convert, table plot, fit of the
    generating model (Lambert + two GGX lobes) from defaults, error against run time for a few
    models and solvers, and a Mitsuba validation of the fit against the tabulated measurement.
    Returns the written files by role and whether the fit converged."""
    from rich.console import Console

    from ._files import atomic_dir
    from .cli.compare import print_report
    from . import plot
    from .cli.info import print_info
    from .fitting import compare, fit
    from .io import save
    from .render import validate

    console = console or Console()
    out = Path(out)
    m, origin = sample_measurement()
    written: dict[str, Path] = {}
    with atomic_dir(out, force=force) as tmp:
        console.rule("[bold]1. load + info")
        print_info(m, "exr" if origin.endswith(".exr") else "sample", origin, console=console)

        console.rule("[bold]2. convert")
        save(m, tmp / "sample_ubo81.npz")
        console.print(f"wrote {out / 'sample_ubo81.npz'} (wi, wo, values, weights, metadata)")
        written["npz"] = out / "sample_ubo81.npz"

        console.rule("[bold]3. plot the 81 x 81 table")
        plot.table(m).savefig(tmp / "table.png", dpi=110)
        console.print(f"wrote {out / 'table.png'}")
        written["table_png"] = out / "table.png"

        console.rule("[bold]4. fit lambert+ggx+ggx from defaults (log loss, Levenberg-Marquardt)")
        with console.status("fitting"):
            result = fit(m, "lambert+ggx+ggx")
        console.print(repr(result), soft_wrap=True)
        _print_recovery(result, console)
        (tmp / "fit").mkdir()
        result.to_json(tmp / "fit" / "fit.json")
        plot.fit_figure(m, result).savefig(tmp / "fit" / "fit.png", dpi=110)
        written["fit_json"] = out / "fit" / "fit.json"
        written["fit_png"] = out / "fit" / "fit.png"

        console.rule("[bold]5. error against run time")
        with console.status("fitting every model x solver"):
            report = compare(m, DEMO_MODELS, DEMO_SOLVERS, ("log",))
        print_report(report, "log", console)
        (tmp / "compare").mkdir()
        report.to_csv(tmp / "compare" / "report.csv")
        report.to_json(tmp / "compare" / "report.json")
        report.plot().savefig(tmp / "compare" / "pareto.png", dpi=120)
        written["pareto_png"] = out / "compare" / "pareto.png"

        console.rule("[bold]6. validate in Mitsuba 3: fit vs measured table, sweep of 5 lights")
        with console.status("rendering"):
            validation = validate(m, result, size=size, out=tmp / "validation", force=True)
        console.print(repr(validation), soft_wrap=True)
        written["validation"] = out / "validation"
        written["metrics_json"] = out / "validation" / "metrics.json"
    console.rule("[bold]done")
    console.print(f"results in {out}/: table.png, fit/, compare/pareto.png, validation/ (EXRs, panels, metrics.json)")
    return DemoResult(files=written, converged=bool(result.converged))


def _print_recovery(result, console) -> None:
    """The fitted parameters beside the generator's ground truth (lobes matched by roughness)."""
    from rich.table import Table

    from .sample import TRUTH

    params = {k: np.asarray(v) for k, v in result.params.items()}
    lobes = sorted((1, 2), key=lambda k: float(params[f"ggx{k}.alpha"][0]))  # sharp lobe first
    rows = [("kd", TRUTH["kd"], params["kd"])]
    for label, k in zip(("sharp", "broad"), lobes):
        for name in ("ks", "alpha", "f0"):
            rows.append((f"{label} lobe {name} (ggx{k}.{name})", TRUTH[label][name], params[f"ggx{k}.{name}"]))
    table = Table(title="fitted vs ground truth of the generator (brdffit.sample.TRUTH)")
    for col in ("parameter", "truth", "fitted"):
        table.add_column(col)
    for name, truth, value in rows:
        table.add_row(name, np.array2string(np.atleast_1d(truth), precision=3),
                      np.array2string(np.atleast_1d(value), precision=3))
    from .cli.compare import print_wide

    print_wide(console, table)
