"""Histograms of the spheres shown at the time shown: speed, contact count, normal force (issue
54, item 5), as OVITO's histogram modifier gives them.

`frame_histograms` is pure numpy: counts from a frame's velocities and contacts (the engine's
recorded normal forces, `viewer.state.Links.force`), restricted to the spheres the clip plane
leaves (a contact counts when every sphere it touches is shown). `Histograms` draws them as
filled step outlines in viser's uPlot (bars are a drawing path uPlot takes as a JavaScript
function, which viser cannot send), updated in place when the time changes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import viser

from viewer.clip import links_shown
from viewer.plots import display_scale
from viewer.state import Frame

BINS = 20
HEIGHT = 170
COLOURS = {"speed": "#4285f4", "contacts per sphere": "#34a853", "normal force": "#aa0014"}


@dataclass
class Histogram:
    """Counts (B,) in bins with these edges (B + 1,), of `total` values (all counted)."""

    title: str
    unit: str
    edges: np.ndarray
    counts: np.ndarray
    total: int
    mean: float

    def outline(self) -> tuple[np.ndarray, np.ndarray]:
        """The histogram as a closed step line (x, y): up and across each bin, down at the end."""
        x = np.concatenate(([self.edges[0]], np.repeat(self.edges[1:-1], 2), [self.edges[-1]]))
        y = np.repeat(self.counts.astype(float), 2)
        return np.concatenate(([x[0]], x, [x[-1]])), np.concatenate(([0.0], y, [0.0]))


def _binned(title: str, unit: str, values: np.ndarray, bins: int = BINS) -> Histogram:
    values = np.asarray(values, float)
    hi = float(values.max()) if len(values) else 0.0
    edges = np.linspace(0.0, hi if hi > 0 else 1.0, bins + 1)
    counts = np.histogram(values, bins=edges)[0]
    return Histogram(title, unit, edges, counts, len(values), float(values.mean()) if len(values) else 0.0)


def count_histogram(counts: np.ndarray) -> Histogram:
    """Contacts per sphere: one bin per whole number, 0 to the largest."""
    counts = np.asarray(counts, np.int64)
    top = int(counts.max(initial=0))
    edges = np.arange(top + 2) - 0.5
    return Histogram("contacts per sphere", "", edges, np.bincount(counts, minlength=top + 1).astype(np.int64),
                     len(counts), float(counts.mean()) if len(counts) else 0.0)


def frame_histograms(frame: Frame, hidden: np.ndarray) -> list[Histogram]:
    """Speed (m/s) and contact count of each shown sphere, and the normal force (N) of each
    contact between shown spheres (or a shown sphere and a wall), at the frame's time."""
    shown = ~np.asarray(hidden, bool)
    n = len(frame.positions)
    speed = np.linalg.norm(frame.velocities, axis=-1) if frame.velocities is not None else np.zeros(n)
    links = frame.contact_links()
    counts = links.counts(n)  # every contact of each sphere, hidden neighbours too
    keep = links_shown(links.i, links.j, ~shown)
    return [_binned("speed", "m/s", speed[shown]), count_histogram(counts[shown]),
            _binned("normal force", "N", links.force[keep])]


class Histograms:
    """The three histograms in a tab of their own, created once and updated in place."""

    def __init__(self, gui: viser.GuiApi, container: Any) -> None:
        self.gui = gui
        self.container = container
        self._handles: dict[str, viser.GuiUplotHandle] = {}
        self._units: dict[str, str] = {}
        with container:
            self.note = gui.add_markdown("", order=-1)

    def show(self, histograms: list[Histogram], note: str) -> None:
        self.note.content = note
        for order, h in enumerate(histograms):
            x, y = h.outline()
            # uPlot's tick labels keep three decimals: values brought into [1, 1000) first.
            factor, unit = display_scale({"x": h.edges}, h.unit) if h.unit else (1.0, "")
            x = x * factor
            scales = {"x": {"time": False, "auto": False,
                            "range": [float(h.edges[0]) * factor, float(h.edges[-1]) * factor]},
                      "y": {"auto": False, "range": [0.0, max(1.0, 1.1 * float(h.counts.max(initial=0)))]}}
            title = self._title(h)
            handle = self._handles.get(h.title)
            if handle is not None:
                handle.data = (x, y)
                handle.scales = scales
                if handle.title != title:
                    handle.title = title
                if self._units.get(h.title) != unit:
                    handle.axes = self._axes(h, unit)
                    self._units[h.title] = unit
                continue
            colour = COLOURS.get(h.title, "#4285f4")
            series = ({"label": h.unit or "contacts"},
                      {"label": "count", "stroke": colour, "width": 1.5, "fill": colour + "55",
                       "points": {"show": False}})
            with self.container:
                self._handles[h.title] = self.gui.add_uplot(
                    (x, y), series, title=title, height=HEIGHT, scales=scales,
                    axes=self._axes(h, unit),
                    legend={"show": False}, cursor={"show": True, "x": True, "y": False}, order=order)
                self._units[h.title] = unit

    @staticmethod
    def _axes(h: Histogram, unit: str) -> tuple:
        return ({"label": f"{h.title} ({unit})" if unit else h.title, "size": 36, "labelSize": 14}, {"size": 46})

    @staticmethod
    def _title(h: Histogram) -> str:
        what = "contacts" if h.title == "normal force" else "spheres"
        unit = f" {h.unit}" if h.unit else ""
        return f"{h.title}: {h.total} {what}, mean {h.mean:.3g}{unit}"
