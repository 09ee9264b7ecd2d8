"""Live plots (viser's uPlot): energy, momentum, angular momentum and compression against time.

The time axis is fixed to the window shown (the whole run, or its first contact) by an explicit
range on every update: uPlot's own auto range, with viser's "keep the relative zoom" logic,
broke after fast changes between runs of very different lengths (issue 12, item 1). Hovering a
plot reads every line's value at the pointer in the legend. Each plot carries a dashed vertical
line at the timeline's cursor. uPlot shares one x array
between series, so the cursor is two extra rows at the cursor time: the other lines pass
through them at their interpolated values. The cursor series has a scale of its own, fixed to
[0, 1]: it is 0 and 1 on its two rows and far below the plot everywhere else, so what shows is
a vertical line at the cursor. (viser sends Float64Arrays, which cannot hold uPlot's null gaps,
and a NaN would spoil the y range.)
"""

from __future__ import annotations

from typing import Any

import numpy as np
import viser
import viser.uplot as uplot

from viewer.state import Series, ViewRun, format_residual

PALETTE = {
    "kinetic": "#4285f4", "rotational": "#ab47bc", "spring": "#f4842a", "gravitational": "#8d6e63",
    "total": "#202124", "dissipated": "#9aa0a6", "total + dissipated": "#34a853",
    "px": "#db4437", "py": "#4285f4", "pz": "#34a853", "Lx": "#db4437", "Ly": "#4285f4", "Lz": "#7b1fa2",
}
EXTRA = ["#f4842a", "#4285f4", "#34a853", "#ab47bc", "#db4437", "#607d8b"]
CURSOR_COLOUR = "#5f6368"
CURSOR_OFF = -0.5  # the cursor series away from the cursor: below its [0, 1] scale, clipped
PLOT_HEIGHT = 190
# Axis labels; the y axis's unit is in each plot's title.
AXES = ({"label": "time (ms)", "size": 36, "labelSize": 14}, {"size": 52})


def _series_style(name: str, k: int) -> uplot.Series:
    style: dict = {"label": name, "stroke": PALETTE.get(name, EXTRA[k % len(EXTRA)]), "width": 1.6,
                   "points": {"show": False}}
    if name in ("dissipated", "total + dissipated"):
        style["dash"] = [6, 4]
    return style  # type: ignore[return-value]


_PREFIXES = {"J": {-3: "mJ", -6: "µJ", -9: "nJ", 3: "kJ"}, "mm": {-3: "µm", 3: "m"}}


def display_scale(lines: dict[str, np.ndarray], unit: str, scale: float = 0.0) -> tuple[float, str]:
    """A factor that brings the quantity's size into [1, 1000), and the unit it implies.

    The size is `scale` (the quantity's natural size) when given, else the largest value: a
    conserved quantity that is zero up to round-off keeps its natural unit instead of 1e-21.
    uPlot's tick labels keep three decimals, so 2.7e-4 would read "-0" without it.
    """
    values = np.concatenate([np.abs(y[np.isfinite(y)]) for y in lines.values()] + [np.zeros(1)])
    peak = scale if scale > 0 else float(values.max())
    if not peak > 0:
        return 1.0, unit
    exp = 3 * int(np.floor(np.log10(peak) / 3))
    if exp == 0:
        return 1.0, unit
    named = _PREFIXES.get(unit, {}).get(exp)
    return 10.0 ** -exp, named if named else f"1e{exp} {unit}"


def y_range(lines: dict[str, np.ndarray], scale: float = 0.0) -> tuple[float, float]:
    """A y range that shows every line, padded, and spans at least a fifth of the quantity's
    size (`scale`, or its largest value): a quantity constant up to round-off (momentum,
    angular momentum) is drawn flat instead of magnifying its last digits."""
    values = np.concatenate([y[np.isfinite(y)] for y in lines.values()] + [np.zeros(0)])
    if not len(values):
        return 0.0, 1.0
    lo, hi = float(values.min()), float(values.max())
    size = max(abs(lo), abs(hi), scale)
    half = 0.54 * max(hi - lo, 0.2 * size, 1e-30)
    mid = 0.5 * (lo + hi)
    return mid - half, mid + half


def with_cursor(times: np.ndarray, lines: dict[str, np.ndarray], t: float) -> tuple[np.ndarray, ...]:
    """uPlot data (x, y..., cursor) with the cursor's two rows inserted at time t."""
    k = int(np.searchsorted(times, t, side="right"))
    x = np.concatenate((times[:k], [t, t], times[k:]))
    ys = []
    for y in lines.values():
        yt = float(np.interp(t, times, y))
        ys.append(np.concatenate((y[:k], [yt, yt], y[k:])))
    cursor = np.full(len(x), CURSOR_OFF)
    cursor[k], cursor[k + 1] = 0.0, 1.0
    return (x, *ys, cursor)


class Plots:
    """The plots of one client, created on the first run and updated in place afterwards."""

    def __init__(self, gui: viser.GuiApi, container: Any) -> None:
        self.gui = gui
        self.container = container
        self._handles: dict[str, viser.GuiUplotHandle] = {}
        self._layout: dict[str, tuple] = {}
        self._series: dict[str, Series] = {}
        self._times: np.ndarray | None = None
        self.window: tuple[float, float] = (0.0, 1.0)  # ms: the time axis shown
        with container:
            self.residuals = gui.add_markdown("", order=100)
        self.cursor_t = 0.0

    def show_run(self, view: ViewRun, t: float, window: tuple[float, float] | None = None) -> None:
        """Plot a run's series with the cursor at t (s) over `window` (s; default: the whole
        run). Same layout: update the data, new layout: rebuild."""
        self._times = view.plots.times * 1e3  # the time axis is in ms, like the timeline
        self.cursor_t = t
        lo, hi = window if window is not None else (view.t0, view.t1)
        self.window = (lo * 1e3, max(hi * 1e3, lo * 1e3 + 1e-9))
        wanted = {s.title: s for s in view.plots.all}
        for title in list(self._handles):
            if title not in wanted:
                self._handles.pop(title).remove()
                self._layout.pop(title, None)
        for order, (title, series) in enumerate(wanted.items()):
            factor, unit = display_scale(series.lines, series.unit, series.scale)
            series = Series(series.title, unit, {k: v * factor for k, v in series.lines.items()},
                            series.scale * factor, series.flat)
            names = (unit, *series.lines)
            data = with_cursor(self._times, series.lines, t * 1e3)
            handle = self._handles.get(title)
            scales = self._scales(series)
            if handle is not None and self._layout.get(title) == names:
                handle.scales = scales
                handle.data = data
            else:
                if handle is not None:
                    handle.remove()
                styles = [{"label": "t (ms)"}] + [_series_style(n, k) for k, n in enumerate(series.lines)]
                styles.append({"label": "now", "stroke": CURSOR_COLOUR, "width": 1, "dash": [3, 3],
                               "points": {"show": False}, "scale": "cursor"})
                with self.container:
                    self._handles[title] = self.gui.add_uplot(
                        data, tuple(styles), title=f"{title} ({series.unit})", height=PLOT_HEIGHT,
                        scales=scales, axes=AXES,
                        # Live legend: hovering a plot reads each line's value at the pointer.
                        legend={"show": True, "live": True}, cursor={"show": True, "x": True, "y": False},
                        order=order,
                    )
                self._layout[title] = names
            self._series[title] = series
        self.residuals.content = residual_markdown(view)

    def _scales(self, series: Series) -> dict:
        # An explicit time range (not uPlot's auto range): see the module docstring.
        return {"x": {"time": False, "auto": False, "range": list(self.window)},
                "y": {"auto": False, "range": list(y_range(series.lines, series.scale))},
                "cursor": {"auto": False, "range": [0.0, 1.0]}}

    def set_window(self, window: tuple[float, float]) -> None:
        """Show the time window (s) on every plot's axis."""
        self.window = (window[0] * 1e3, max(window[1] * 1e3, window[0] * 1e3 + 1e-9))
        for title, handle in self._handles.items():
            handle.scales = self._scales(self._series[title])

    def show_cursor(self, t: float) -> None:
        """Move the cursor line of every plot to time t (s)."""
        if self._times is None:
            return
        self.cursor_t = t
        for title, handle in self._handles.items():
            handle.data = with_cursor(self._times, self._series[title].lines, t * 1e3)

    def remove(self) -> None:
        for handle in self._handles.values():
            handle.remove()
        self._handles.clear()


def residual_markdown(view: ViewRun) -> str:
    """The residuals as numbers, with what each one measures."""
    res = view.residuals
    notes = []
    if view.friction:
        notes.append("energy: balance including the work dissipated by friction")
    if view.n_walls:
        notes.append("momentum and angular momentum are not conserved with walls")
    if view.dim == 1:
        notes.append("no angular momentum in 1D")
    flat = [f"{s.title} ({', '.join(s.flat)})" for s in (view.plots.momentum, view.plots.angular_momentum)
            if s is not None and s.flat]
    if flat:
        notes.append("constant to round-off, drawn flat: " + "; ".join(flat))
    rows = [f"| energy | {format_residual(res['energy'])} |",
            f"| momentum | {format_residual(res['momentum'])} |",
            f"| angular momentum | {format_residual(res['angular_momentum'])} |"]
    text = "**Residuals** (relative, end vs start)\n\n| quantity | residual |\n|---|---|\n" + "\n".join(rows)
    if notes:
        text += "\n\n" + "; ".join(notes) + "."
    return text
