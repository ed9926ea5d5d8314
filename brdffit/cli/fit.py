"""``brdffit fit SOURCE --model M [--loss L] [--solver S] -o DIR``: one fit (SPEC 7).

Writes DIR/fit.json (``FitResult.to_json``) and DIR/fit.png: for a UBO-81 measurement the 81x81
table measured | fitted | log-ratio (light rows, view columns, log colour scale); for scattered
samples, fitted against measured values per channel. Exit 1 when the fit did not converge (the
results are still written; fit.json says ``"converged": false``).
"""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from . import EXIT_NOT_CONVERGED, EXIT_OK, cli


def plot_fit(measurement, result, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    mask = measurement.valid_mask()
    fitted = result.eval(np.asarray(measurement.wi), np.asarray(measurement.wo))
    ref = np.asarray(measurement.values)
    title = f"{result.model_name} ({result.solver}, {result.loss} loss) on {measurement.name}: {result.status}"
    if measurement.grid == "ubo81":
        lum_ref = ref.mean(axis=1).reshape(81, 81)
        lum_fit = fitted.mean(axis=1).reshape(81, 81)
        valid = mask.reshape(81, 81)
        pos = lum_ref[valid & (lum_ref > 0)]
        vmin = max(float(np.percentile(pos, 1)) if pos.size else 1e-3, 1e-6)
        vmax = max(float(lum_ref[valid].max()), float(lum_fit.max()), vmin * 10)
        fig, axes = plt.subplots(1, 3, figsize=(15, 5), dpi=110)
        for ax, img, name in ((axes[0], lum_ref, "measured"), (axes[1], lum_fit, "fitted")):
            im = ax.imshow(np.where(valid, np.maximum(img, vmin), np.nan), norm=LogNorm(vmin, vmax), cmap="magma")
            ax.set_title(f"{name} (mean of channels, 1/sr)")
            ax.set_xlabel("view index")
            ax.set_ylabel("light index")
            fig.colorbar(im, ax=ax, fraction=0.046)
        ratio = np.log10(np.maximum(lum_fit, 1e-9) / np.maximum(lum_ref, 1e-9))
        im = axes[2].imshow(np.where(valid, ratio, np.nan), cmap="coolwarm", vmin=-1, vmax=1)
        axes[2].set_title("log10(fitted / measured)")
        axes[2].set_xlabel("view index")
        fig.colorbar(im, ax=axes[2], fraction=0.046)
    else:
        fig, ax = plt.subplots(figsize=(6.5, 6), dpi=110)
        colours = ("tab:red", "tab:green", "tab:blue") if ref.shape[1] == 3 else ("k",)
        lo = max(float(np.min(ref[mask][ref[mask] > 0], initial=1e-3)), 1e-6)
        hi = float(max(ref[mask].max(), fitted[mask].max()))
        for c in range(ref.shape[1]):
            ax.scatter(np.maximum(ref[mask, c], lo), np.maximum(fitted[mask, c], lo), s=4, alpha=0.5,
                       color=colours[c % len(colours)], label=f"channel {c}")
        ax.plot([lo, hi], [lo, hi], "k--", lw=0.8, label="fitted = measured")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("measured f_r [1/sr]")
        ax.set_ylabel("fitted f_r [1/sr]")
        ax.legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


@cli.command("fit")
@click.argument("source", type=click.Path(path_type=str))
@click.option("--model", "-m", "model", required=True, help="Model name, e.g. ggx or lambert+ggx+ggx.")
@click.option("--loss", default="log", show_default=True, help="l2 | cosine_l2 | log | cbrt | relative")
@click.option("--solver", default="lm", show_default=True, help="lm | lmb | gauss_newton | dogleg | bfgs | scipy")
@click.option("--multistart", default=0, show_default=True, help="Further grid starts to polish.")
@click.option("--max-steps", default=200, show_default=True)
@click.option("-o", "--out", "out", default=None, type=click.Path(path_type=Path), help="Output folder [fit-<name>-<model>].")
@click.option("--force", is_flag=True, help="Replace an existing output folder.")
@click.option("--scene", default=None, type=click.Path(path_type=str), help="Mitsuba 3 scene: fit where it looks at --material.")
@click.option("--material", default=None, help="Id of the BSDF in --scene that this fit is for.")
def fit_command(source, model, loss, solver, multistart, max_steps, out, force, scene, material) -> int:
    """Fit one model to one measurement; writes fit.json and fit.png."""
    from rich.console import Console

    from .. import load
    from .._files import atomic_dir, check_target
    from ..fitting import fit
    from ..fitting.losses import check_loss
    from ..fitting.problem import resolve_model
    from ..fitting.solve import check_solver

    check_loss(loss)
    check_solver(solver)
    resolve_model(model, 3)  # unknown model -> usage error before any work
    console = Console(stderr=True)
    usage = None
    if scene is not None or material is not None:  # SPEC 12: scene-aware fit
        from ..scene.usage import cli_usage

        with console.status(f"recording where {scene} looks at {material!r}"):
            m, usage = cli_usage(source, scene, material)
    else:
        with console.status(f"loading {source}"):
            m = load(source)
    out = out or Path(f"fit-{m.name}-{model.replace('+', '_')}")
    check_target(out, force)
    with console.status(f"fitting {model} to {m.name} ({loss} loss, {solver})"):
        r = fit(m, model, loss=loss, solver=solver, multistart=multistart, max_steps=max_steps,
                scene=usage)
    with atomic_dir(out, force) as tmp:
        r.to_json(tmp / "fit.json")
        plot_fit(m, r, tmp / "fit.png")
    console.print(repr(r), soft_wrap=True)
    console.print(f"wrote {out}/fit.json, {out}/fit.png")
    if not r.converged:
        console.print(f"[bold red]not converged[/]: {r.status}")
        return EXIT_NOT_CONVERGED
    return EXIT_OK
