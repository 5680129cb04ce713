"""The sweep's figures: amplitude and wavelength curves, and the pattern-class phase map.

matplotlib is imported by the functions that draw, on the Agg canvas.
"""

from __future__ import annotations

import math
from collections import Counter, defaultdict
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cnt_env.io import OutputSet

__all__ = ["PATTERN_COLORS", "plot_sweep", "row_class"]

# Colours of the pattern classes in every plot (patterns.PATTERNS, then the sweep's own).
PATTERN_COLORS: dict[str, str] = {
    "coil": "tab:blue",
    "serpentine-coil": "tab:purple",
    "periodic-serpentine": "tab:green",
    "irregular-serpentine": "tab:orange",
    "straight": "tab:olive",
    "unknown": "tab:brown",
    "not measured": "0.75",
    "failed": "tab:red",
    "not run": "white",
}


def _float(value: Any) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def row_class(row: Mapping[str, Any] | None) -> str:
    """The pattern class a plot shows for a row (or "failed", "not measured", "not run")."""
    if row is None:
        return "not run"
    if row.get("pattern"):
        return str(row["pattern"])
    failure = str(row.get("failure") or "")
    return "not measured" if failure.startswith("not measured") or not failure else "failed"


def _use_log(values: Sequence[float]) -> bool:
    finite = [v for v in values if math.isfinite(v)]
    return bool(finite) and min(finite) > 0.0 and max(finite) / min(finite) >= 20.0


def _class_handles(classes: Iterable[str]) -> list[Any]:
    from matplotlib.patches import Patch

    order = list(PATTERN_COLORS)
    present = sorted(set(classes), key=lambda c: order.index(c) if c in order else len(order))
    return [
        Patch(facecolor=PATTERN_COLORS.get(c, "0.5"), edgecolor="0.3", label=c) for c in present
    ]


def _plot_curves(rows: Sequence[Mapping[str, Any]], params: Sequence[str], path: Path) -> Path:
    """Amplitude and wavelength against params[0]: markers coloured by pattern class,
    bars the within-run p16-p84 spread, the line the median over repeated points (or,
    on a 2-D grid, one line per value of params[1])."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    x_name = params[0]
    fig = Figure(figsize=(11.0, 4.6), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, 2)
    groups: dict[float, list[Mapping[str, Any]]] = defaultdict(list)
    for row in rows:
        groups[_float(row[params[1]]) if len(params) > 1 else math.nan].append(row)
    two_d = len(params) > 1
    cmap = None
    if two_d:
        from matplotlib import colormaps

        cmap = colormaps["viridis"]
    keys = sorted(groups, key=lambda v: (math.isnan(v), v))
    for ax, quantity in zip(axes, ("amplitude", "wavelength"), strict=True):
        for gi, key in enumerate(keys):
            group = groups[key]
            line_color = cmap(gi / max(1, len(keys) - 1)) if cmap is not None else "0.4"
            by_x: dict[float, list[float]] = defaultdict(list)
            for row in group:
                x, y = _float(row[x_name]), _float(row.get(quantity))
                by_x[x].append(y)
                if not (math.isfinite(x) and math.isfinite(y)):
                    continue
                lo, hi = _float(row.get(f"{quantity}_p16")), _float(row.get(f"{quantity}_p84"))
                if math.isfinite(lo) and math.isfinite(hi):
                    yerr = [[max(0.0, y - lo)], [max(0.0, hi - y)]]
                    ax.errorbar(
                        [x], [y], yerr=yerr, fmt="none", ecolor="0.6", elinewidth=0.8, capsize=2
                    )
                ax.plot(
                    [x],
                    [y],
                    "o",
                    ms=6,
                    color=PATTERN_COLORS.get(row_class(row), "0.5"),
                    mec=line_color if two_d else "0.2",
                    mew=1.2 if two_d else 0.6,
                    zorder=3,
                )
            xs = sorted(x for x in by_x if math.isfinite(x))
            med = [
                float(np.median([y for y in by_x[x] if math.isfinite(y)]))
                if any(math.isfinite(y) for y in by_x[x])
                else math.nan
                for x in xs
            ]
            ax.plot(xs, med, "-", lw=1.0, color=line_color, zorder=2)
        if _use_log([_float(r[x_name]) for r in rows]):
            ax.set_xscale("log")
        ax.set_xlabel(x_name)
        ax.set_ylabel(f"{quantity} (L_vb)")
        ax.set_title(f"{quantity} (bars: p16-p84 over the trace)")
        ax.grid(alpha=0.3)
    handles = _class_handles(row_class(r) for r in rows)
    if two_d:
        handles += [
            Line2D([], [], color=cmap(i / max(1, len(keys) - 1)), label=f"{params[1]} = {k:.4g}")
            for i, k in enumerate(keys)
        ]
    axes[1].legend(handles=handles, loc="best", fontsize="small")
    fig.suptitle(f"sweep over {' x '.join(params)}: serpentine amplitude and wavelength")
    fig.savefig(path, format="png", dpi=120)
    return path


def _plot_phase(
    rows: Sequence[Mapping[str, Any]],
    params: Sequence[str],
    grids: Sequence[Sequence[float]],
    path: Path,
) -> Path:
    """Pattern class over the 2-D grid (the most common class over repeated points)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.colors import ListedColormap
    from matplotlib.figure import Figure

    xs = sorted(set(grids[0]))
    ys = sorted(set(grids[1]))
    cells: dict[tuple[float, float], Counter] = defaultdict(Counter)
    for row in rows:
        cells[(_float(row[params[0]]), _float(row[params[1]]))][row_class(row)] += 1
    order = list(PATTERN_COLORS)
    grid_class = [
        [cells[(x, y)].most_common(1)[0][0] if cells[(x, y)] else "not run" for x in xs] for y in ys
    ]
    present = sorted(
        {c for line in grid_class for c in line},
        key=lambda c: order.index(c) if c in order else len(order),
    )
    index = {c: i for i, c in enumerate(present)}
    data = np.array([[index[c] for c in line] for line in grid_class], dtype=float)
    cmap = ListedColormap([PATTERN_COLORS.get(c, "0.5") for c in present])

    fig = Figure(figsize=(7.5, 5.5), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    ax.pcolormesh(
        np.arange(len(xs) + 1) - 0.5,
        np.arange(len(ys) + 1) - 0.5,
        data,
        cmap=cmap,
        vmin=-0.5,
        vmax=len(present) - 0.5,
        edgecolors="0.3",
        linewidth=0.5,
    )
    for j, y in enumerate(ys):
        for i, x in enumerate(xs):
            group = [r for r in rows if _float(r[params[0]]) == x and _float(r[params[1]]) == y]
            amps = [_float(r.get("amplitude")) for r in group]
            amps = [a for a in amps if math.isfinite(a)]
            if amps:
                ax.text(i, j, f"A={np.median(amps):.3g}", ha="center", va="center", fontsize=7)
    ax.set_xticks(range(len(xs)), [f"{v:.4g}" for v in xs], rotation=45, ha="right")
    ax.set_yticks(range(len(ys)), [f"{v:.4g}" for v in ys])
    ax.set_xlabel(params[0])
    ax.set_ylabel(params[1])
    ax.set_title(f"pattern class over {params[0]} x {params[1]} (A: amplitude, L_vb)")
    ax.legend(
        handles=_class_handles(present),
        loc="upper left",
        bbox_to_anchor=(1.01, 1.0),
        fontsize="small",
    )
    fig.savefig(path, format="png", dpi=120)
    return path


def plot_sweep(
    rows: Sequence[Mapping[str, Any]],
    params: Sequence[str],
    grids: Sequence[Sequence[float]],
    outdir: Path,
    stem: str = "sweep",
    outputs: OutputSet | None = None,
) -> list[Path]:
    """Write the sweep's figures to ``outdir``: ``<stem>_curves.png`` always and
    ``<stem>_phase.png`` for a 2-D grid. matplotlib is imported here, on Agg. With
    ``outputs`` they are staged there (written into place by its commit)."""
    outdir.mkdir(parents=True, exist_ok=True)
    staged = outputs if outputs is not None else OutputSet()
    finals = [outdir / f"{stem}_curves.png"]
    if len(params) > 1:
        finals.append(outdir / f"{stem}_phase.png")
    try:
        tmps = [staged.add(path, "--plots") for path in finals]
        _plot_curves(rows, params, tmps[0])
        if len(params) > 1:
            _plot_phase(rows, params, grids, tmps[1])
    except BaseException:
        staged.discard()
        raise
    if outputs is None:
        staged.commit()
    return finals
