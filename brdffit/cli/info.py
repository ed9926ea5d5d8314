"""``brdffit info SOURCE``: what a measurement holds (docs/cli.md#the-command-line-and-set-up)."""

from __future__ import annotations

import click

from . import cli


def _fmt(x: float) -> str:
    return f"{x:.4g}"


def _meta_text(key: str, value) -> str:
    """A metadata value for display: angles to 0.1 degree, other floats to 4 significant digits."""
    if isinstance(value, float):
        return f"{value:.1f} deg" if key.endswith("_deg") else f"{value:.4g}"
    return str(value)


@cli.command("info")
@click.argument("source", type=click.Path(path_type=str))
def info(source: str) -> int:
    """Show format, samples, grid, channels, value ranges, invalid samples and direction coverage."""
    from ..io import detect_format, load

    fmt = detect_format(source)
    print_info(load(source, progress=True), fmt, str(source))
    return 0


def print_info(m, fmt: str, source: str, console=None) -> None:
    """Print what ``brdffit info`` shows for a loaded measurement."""
    from rich.console import Console
    from rich.table import Table

    from ..io import summary

    s = summary(m)
    console = console or Console()
    head = Table(show_header=False, box=None, pad_edge=False)
    head.add_column(style="bold")
    head.add_column()
    origin = s["format"]
    head.add_row("source", str(source))
    head.add_row("format", fmt if origin in (fmt, "?") else f"{fmt} (origin: {origin})")
    head.add_row("name", s["name"])
    head.add_row("samples", str(s["samples"]))
    head.add_row("grid", str(s["grid"] or "scattered"))
    head.add_row("channels", f"{s['channels']} ({s['colour_space']}, {s['units']})")
    head.add_row(
        "invalid samples",
        f"{s['invalid']} (weight 0: {s['zero_weight']}, non-finite: {s['non_finite']})",
    )
    negative = sum(r["negative"] for r in s["ranges"])
    head.add_row("negative values", f"{negative} (channel values < 0 in valid samples; kept)")
    head.add_row("theta light", f"{s['theta_light_deg'][0]:.1f} .. {s['theta_light_deg'][1]:.1f} deg")
    head.add_row("theta view", f"{s['theta_view_deg'][0]:.1f} .. {s['theta_view_deg'][1]:.1f} deg")
    for key in ("interpolation", "extrapolated", "max_extrapolation_deg", "light_directions"):
        if key in m.meta:
            head.add_row(key.replace("_", " "), _meta_text(key, m.meta[key]))
    console.print(head)
    ranges = Table(title="values over valid samples (1/sr)", title_justify="left")
    for col in ("channel", "min", "max", "mean", "negative"):
        ranges.add_column(col, justify="right")
    for r in s["ranges"]:
        ranges.add_row(r["channel"], _fmt(r["min"]), _fmt(r["max"]), _fmt(r["mean"]), str(r["negative"]))
    console.print(ranges)
