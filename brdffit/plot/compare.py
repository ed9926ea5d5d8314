"""Error against run time of a :class:`~brdffit.fitting.compare.Report`: :func:`pareto`."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ._common import new_figure

if TYPE_CHECKING:
    from ._figure import Figure


# -- error against run time --------------------------------------------------------------------------
def pareto(report, metric: str = "loss_log") -> Figure:
    """Error (``metric``) against run time, log axes: colour = model, marker = solver; the rows of
    ``report.pareto(metric)`` are labelled and joined (ties keep the fastest, docs/fitting.md#fitting)."""
    import matplotlib
    from matplotlib.lines import Line2D

    rows = [r for r in report.rows if r[metric] > 0 and r["run_s"] > 0]
    front = [r for r in report.pareto(metric) if r in rows]
    fig = new_figure((9, 6.5), layout="constrained")
    ax = fig.add_subplot()
    solvers = sorted({r["solver"] for r in rows})
    markers = dict(zip(solvers, "osD^v<>p*hX"))
    models = sorted({r["model"] for r in rows})
    cmap = matplotlib.colormaps["tab20" if len(models) > 10 else "tab10"]
    colours = {m: cmap(i % cmap.N) for i, m in enumerate(models)}
    for r in rows:
        ax.scatter(r["run_s"], r[metric], marker=markers[r["solver"]], color=colours[r["model"]], s=46,
                   edgecolors="black" if r["converged"] else "red", linewidths=0.6 if r["converged"] else 1.6,
                   zorder=3)
    several_losses = len({x["loss"] for x in rows}) > 1
    for i, r in enumerate(front):
        label = f"{r['model']} / {r['solver']}" + (f" / {r['loss']}" if several_losses else "")
        ax.annotate(label, (r["run_s"], r[metric]), fontsize=7.5, xytext=(6, 6 if i % 2 else -10),
                    textcoords="offset points", bbox=dict(boxstyle="round,pad=0.2", fc="white", ec="none", alpha=0.8))
    if len(front) > 1:
        ax.plot([r["run_s"] for r in front], [r[metric] for r in front], "k--", lw=0.8, zorder=2)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("run time (s, after compilation)")
    ax.set_ylabel(f"{metric.replace('loss_', '')} loss on the measurement")
    ax.set_title(f"error against run time: {report.data_name}")
    ax.grid(True, which="both", alpha=0.3)
    handles = [Line2D([], [], marker=markers[s], ls="", color="grey", label=f"solver {s}") for s in solvers]
    handles += [Line2D([], [], marker="s", ls="", color=colours[m], label=m) for m in models]
    handles.append(Line2D([], [], marker="o", ls="", mfc="white", mec="red", mew=1.6, label="not converged"))
    handles.append(Line2D([], [], ls="--", color="k", label="Pareto front (labelled)"))
    ax.legend(handles=handles, fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    return fig
