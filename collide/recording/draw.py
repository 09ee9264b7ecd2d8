"""What a person looks at in a recording: the 3D view (spheres, spin markers, trails, walls,
contacts and force arrows), the plots (energies, momenta, compression, residuals), the scene and
settings, and the blueprint that lays them out. A part of `writer._Writer`, which holds the run,
its frames and the stream these methods send to (`_send`, `_static`)."""

from __future__ import annotations

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from collide.colours import ENERGY_COLOURS, body_colour, body_colours
from collide.engine import layout
from collide.recording.columns import _strips_column
from collide.recording.frames import _frame_residuals, _pad3, _quaternion_xyzw, _rotate
from collide.recording.spec import TIMELINE, collide_version

_AXES = "xyz"
SWEEP_ROWS = 1 << 18  # knots measured at once for the region the bodies sweep
NORMAL_COLOUR, FRICTION_COLOUR = (255, 215, 0), (255, 64, 160)  # force arrows


def _axis_with_zero(values: np.ndarray) -> rrb.ScalarAxis:
    """A y axis that includes zero: a conserved quantity then plots flat, not as magnified noise."""
    lo, hi = min(float(np.min(values)), 0.0), max(float(np.max(values)), 0.0)
    pad = 0.1 * (hi - lo) if hi > lo else 1.0
    return rrb.ScalarAxis(range=(lo - pad, hi + pad))


class _Drawing:
    """The entities a person looks at, written by `writer._Writer` (which this is a part of)."""

    _swept: tuple[np.ndarray, float] | None = None  # `_extent`, once (a pass over every knot)

    # -- layout ---------------------------------------------------------------------------

    def _extent(self) -> tuple[np.ndarray, float]:
        """Centre and size of the region the bodies sweep (3D), for the camera and the walls."""
        if self._swept is None:
            self._swept = self._sweep()
        return self._swept

    def _sweep(self) -> tuple[np.ndarray, float]:
        knots = self.traj.knots
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        for a in range(0, max(len(knots), 1), SWEEP_ROWS):  # a block at a time: a pour has millions of knots
            part = knots[a:a + SWEEP_ROWS]
            s = _pad3(part[:, layout.K_S:layout.K_S + self.model.dim])
            r = self.model.radius[0][part[:, layout.K_BODY].astype(int)][:, None]
            lo, hi = np.minimum(lo, (s - r).min(axis=0)), np.maximum(hi, (s + r).max(axis=0))
        return 0.5 * (lo + hi), float(max(np.max(hi - lo), 4 * self.model.radius.max()))

    def blueprint(self) -> rrb.Blueprint:
        """3D view (tabs: scene, settings) on the left, plots stacked on the right."""
        centre, size = self._extent()
        if self.model.dim < 3:
            # A 1D or 2D scene seen from above its plane, x to the right and y up.
            eye = rrb.EyeControls3D(position=centre + np.array([0.0, 0.0, 1.1 * size]),
                                    look_target=centre, eye_up=[0.0, 1.0, 0.0])
        else:
            # From the front, right and above, z up, far enough that the whole region the bodies
            # sweep (its bounding sphere, radius 0.87 size) fits the default field of view (Rerun's
            # own choice frames the origin and cut gas-box's box in half).
            direction = np.array([0.55, -0.7, 0.45]) / np.linalg.norm([0.55, -0.7, 0.45])
            eye = rrb.EyeControls3D(position=centre + 2.2 * size * direction, look_target=centre,
                                    eye_up=[0.0, 0.0, 1.0])
        overrides = {} if self.many else {f"/world/{b}/trail": rrb.VisibleTimeRanges(
            timeline=TIMELINE, start=rrb.TimeRangeBoundary.infinite(),
            end=rrb.TimeRangeBoundary.cursor_relative()) for b in self.model.body_names}
        world = rrb.Spatial3DView(origin="/world", name="3D", eye_controls=eye, overrides=overrides)
        left = rrb.Tabs(world, rrb.TextDocumentView(origin="/scene", name="scene"),
                        rrb.TextDocumentView(origin="/settings", name="settings"), active_tab=0)
        legend = rrb.PlotLegend(corner=rrb.Corner2D.RightTop)
        axis = None
        log = self.result.contacts
        if log.count[0] > 0 and np.isfinite(log.last_end[0]):
            # Plots open on the contacts (the interesting part), with as much time either side.
            start, end = float(log.first_start[0]), float(log.last_end[0])
            span = max(end - start, 1e-9)
            axis = rrb.TimeAxis(view_range=rr.TimeRange(
                start=rr.TimeRangeBoundary.absolute(seconds=max(start - span, 0.0)),
                end=rr.TimeRangeBoundary.absolute(seconds=min(end + span, float(self.exact.times[-1])))))

        def plot(origin: str, name: str, values: np.ndarray | None = None) -> rrb.TimeSeriesView:
            return rrb.TimeSeriesView(origin=origin, name=name, plot_legend=legend, axis_x=axis,
                                      axis_y=None if values is None else _axis_with_zero(values))

        plots = [plot("/energy", "energy (J)")]
        c = self.conserved
        motion = [plot("/momentum", "momentum (kg m/s)", c.momentum)]
        if c.angular_momentum is not None:
            motion.append(plot("/angular_momentum", "L (kg m²/s)", c.angular_momentum))
        if self.spin:
            motion.append(plot("/spin", "spin (rad/s)"))
        plots.append(rrb.Tabs(*motion, active_tab=0) if len(motion) > 1 else motion[0])
        if len(self.touched) and not self.many_contacts:
            first = self.exact.contacts.names[0]
            plots.append(rrb.Tabs(plot(f"/contacts/{first}/compression", f"compression {first} (m)"),
                                  plot("/contacts", "all contacts"), active_tab=0))
        elif len(self.touched):
            plots.append(plot("/contacts", "contacts"))
        plots.append(plot("/residuals", "residuals (relative)"))
        return rrb.Blueprint(rrb.Horizontal(left, rrb.Vertical(*plots), column_shares=[3, 2]),
                             rrb.TimePanel(timeline=TIMELINE, state="collapsed"), collapse_panels=True)

    # -- entities -------------------------------------------------------------------------

    def _write_static(self) -> None:
        r = self.result
        self._static("/scene", rr.TextDocument(self.scene.to_toml(), media_type=rr.MediaType.TEXT))
        lines = ["| setting | value |", "|---|---|",
                 f"| scene | {self.scene.name} |", f"| dim | {self.model.dim} |",
                 f"| integrator | {r.integrator} |", f"| dt | {float(r.dt[0]):.6g} s |",
                 f"| steps | {int(r.steps[0])} |", f"| free-flight jumps | {int(r.jumps[0])} |",
                 f"| simulated time | {float(r.final.t[0]):.6g} s |",
                 f"| wall time | {r.wall_time_s:.4g} s |",
                 f"| frames | {len(self.view.times)} (3D), {len(self.exact.times)} (plots) |",
                 f"| stride | {self.stride} |", f"| fps (free flight) | {self.fps:g} |",
                 f"| frames kept | {self._frames_kept()} |",
                 *([f"| DEM frames | {len(self.traj.knot_times)}, one each {r.frame_steps} steps |"]
                   if r.frame_steps > 1 else []),
                 f"| force arrows | {self.force_scale:.4g} m/N |", f"| collide | {collide_version()} |"]
        lines += [f"| warning | {w} |" for w in r.warnings]
        self._static("/settings", rr.TextDocument("\n".join(lines), media_type=rr.MediaType.MARKDOWN))
        self._static("/world", rr.ViewCoordinates.RIGHT_HAND_Z_UP)
        if self.model.n_walls:
            centre, size = self._extent()
            for k in range(self.model.n_walls):
                self._static(f"/world/walls/wall{k}", rr.LineStrips3D(
                    [self._wall_outline(k, centre, size)], colors=[(160, 160, 160)], radii=0.002 * size))

    def _frames_kept(self) -> str:
        """Which frames the 3D view holds (many bodies: every k-th, said here and in the meta)."""
        if self.frame_every == 1:
            return "every frame"
        return (f"every k-th frame, k = {self.frame_every}, of {self.fps * self.frame_every:g} per second "
                f"({self.model.n_bodies} bodies); the trajectory is stored whole")

    def _wall_outline(self, k: int, centre: np.ndarray, size: float) -> np.ndarray:
        """A wall drawn across the region the bodies sweep: a segment (1D, 2D) or a square (3D)."""
        n = _pad3(self.model.wall_normal[k])
        p = _pad3(self.model.wall_point[k])
        foot = centre - np.dot(centre - p, n) * n
        h = 0.6 * size
        if self.model.dim < 3:
            t = np.array([-n[1], n[0], 0.0])
            return np.stack((foot - h * t, foot + h * t))
        a = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
        a /= np.linalg.norm(a)
        b = np.cross(n, a)
        corners = ((-1, -1), (1, -1), (1, 1), (-1, 1), (-1, -1))
        return np.stack([foot + h * (i * a + j * b) for i, j in corners])

    def _write_bodies(self) -> None:
        if self.many:
            self._write_many_bodies()
            return
        view, exact = self.view, self.exact
        centres = _pad3(view.state.s)  # (T, N, 3)
        for n, name in enumerate(self.model.body_names):
            r = float(self.model.radius[0, n])
            color = body_colour(n)
            entity = f"/world/{name}"
            self._static(entity, rr.Ellipsoids3D(half_sizes=[[r, r, r]], colors=[color], labels=[name],
                                                 fill_mode=rr.components.FillMode.MajorWireframe,
                                                 line_radii=0.02 * r))
            c = centres[:, n]
            cols = [*rr.Ellipsoids3D.columns(centers=c)]
            if self.spin:
                cols += [*rr.Ellipsoids3D.columns(quaternions=_quaternion_xyzw(view.state.q[:, n]))]
            self._send(entity, cols, view.index)
            trail = np.stack((np.concatenate((c[:1], c[:-1])), c), axis=1)  # (T, 2, 3): one segment a frame
            self._static(f"{entity}/trail", rr.LineStrips3D.from_fields(colors=[color], radii=0.03 * r))
            self._send(f"{entity}/trail", [_strips_column(trail)], view.index)
            if not self.spin:
                continue
            rim = c + r * _rotate(view.state.q[:, n], np.array([1.0, 0.0, 0.0]))
            marker = rr.LineStrips3D.from_fields(colors=[(235, 235, 235)], radii=0.04 * r)
            self._static(f"{entity}/spin", marker)
            self._send(f"{entity}/spin", [_strips_column(np.stack((c, rim), axis=1))], view.index)
            names = [name] if self.model.spin_dim == 1 else [f"{name}.{a}" for a in _AXES]
            self._static(f"/spin/{name}", rr.SeriesLines(names=names))
            self._send(f"/spin/{name}", rr.Scalars.columns(scalars=exact.state.w[:, n]), exact.index)

    def _write_many_bodies(self) -> None:
        """Every sphere as an instance of one entity: positions each frame, radii and colours
        (one per body, the viewer's: `collide.colours`) once."""
        view = self.view
        centres = _pad3(view.state.s).astype(np.float32)  # (T, N, 3)
        n = self.model.n_bodies
        colors = body_colours(n)
        self._static("/world/bodies", rr.Points3D.from_fields(radii=self.model.radius[0].astype(np.float32),
                                                              colors=colors))
        cols = rr.Points3D.columns(positions=centres.reshape(-1, 3)).partition(np.full(len(view.times), n))
        self._send("/world/bodies", cols, view.index)

    def _contact_bodies(self, c: int) -> list[str]:
        i, j = self.exact.contacts.pairs[c]
        names = self.model.body_names
        return [names[i], names[j]] if j >= 0 else [names[i]]

    def _write_contacts(self) -> None:
        if self.many_contacts:
            self._write_many_contacts()
            return
        view, exact = self.view.contacts, self.exact.contacts
        radius = float(self.model.radius.mean())
        for c in self.touched:
            name = exact.names[c]
            bodies = self._contact_bodies(c)
            on = view.overlap[:, 0, c] > self.pressed
            lengths = on.astype(np.int32)
            point = _pad3(view.point[:, 0, c])[on]
            entity = f"/world/contacts/{name}"
            self._static(f"{entity}/point", rr.Points3D.from_fields(colors=[(0, 0, 0)], radii=0.05 * radius))
            points = rr.Points3D.columns(positions=point).partition(lengths)
            self._send(f"{entity}/point", points, self.view.index)
            self._arrow_style(f"{entity}/normal_force", NORMAL_COLOUR)
            self._arrows(f"{entity}/normal_force", _pad3(view.normal_force[:, 0, c])[on], point, lengths,
                         len(bodies), self.view.index)
            if self.friction:
                self._arrow_style(f"{entity}/friction_force", FRICTION_COLOUR)
                self._arrows(f"{entity}/friction_force", _pad3(view.friction_force[:, 0, c])[on], point,
                             lengths, len(bodies), self.view.index)
            plot = f"/contacts/{name}"
            index = self.exact.index
            self._static(f"{plot}/compression", rr.SeriesLines(names=bodies))
            compression = exact.compression[:, 0, c, :len(bodies)]
            self._send(f"{plot}/compression", rr.Scalars.columns(scalars=compression), index)
            self._send(f"{plot}/overlap", rr.Scalars.columns(scalars=exact.overlap[:, 0, c]), index)
            normal = np.linalg.norm(exact.normal_force[:, 0, c], axis=-1)
            self._send(f"{plot}/normal_force", rr.Scalars.columns(scalars=normal), index)
            if self.friction:
                friction = np.linalg.norm(exact.friction_force[:, 0, c], axis=-1)
                self._send(f"{plot}/friction_force", rr.Scalars.columns(scalars=friction), index)

    def _write_many_contacts(self) -> None:
        """Every contact at once: points and normal (and friction) force arrows of all contacts
        pressed at each frame, a block of frames a call, and how many there are as a plot."""
        radius = float(self.model.radius.mean())
        friction = self.friction
        self._static("/world/contacts/points", rr.Points3D.from_fields(colors=[(0, 0, 0)], radii=0.05 * radius))
        self._arrow_style("/world/contacts/normal_force", NORMAL_COLOUR)
        if friction:
            self._arrow_style("/world/contacts/friction_force", FRICTION_COLOUR)
        for block, view in self._engaged(self.view):  # entries ordered by time, then contact
            on = view.overlap > self.pressed
            lengths = np.bincount(view.tk[on], minlength=block.stop - block.start).astype(np.int32)
            index = rr.TimeColumn(TIMELINE, duration=self.view.times[block])
            point = _pad3(view.point[on])
            self._send("/world/contacts/points", rr.Points3D.columns(positions=point).partition(lengths), index)
            self._arrows("/world/contacts/normal_force", _pad3(view.normal_force[on]), point, lengths, 1, index)
            if friction:
                self._arrows("/world/contacts/friction_force", _pad3(view.friction_force[on]), point, lengths, 1,
                             index)
        self._send("/contacts/count", rr.Scalars.columns(scalars=self.pressed_count), self.exact.index)

    def _arrow_style(self, entity: str, color: tuple[int, int, int]) -> None:
        self._static(entity, rr.Arrows3D.from_fields(colors=[color], radii=0.06 * float(self.model.radius.mean())))

    def _arrows(self, entity: str, force: np.ndarray, point: np.ndarray, lengths: np.ndarray,
                n_bodies: int, index: rr.TimeColumn) -> None:
        """Force on each body of a contact, drawn from the contact point (equal and opposite)."""
        vec = self.force_scale * force
        if n_bodies == 2:
            vec = np.stack((vec, -vec), axis=1).reshape(-1, 3)
            point = np.repeat(point, 2, axis=0)
        columns = rr.Arrows3D.columns(origins=point, vectors=vec).partition(lengths * n_bodies)
        self._send(entity, columns, index)

    def _write_conserved(self) -> None:
        model, st, index, c = self.model, self.exact.state, self.exact.index, self.conserved
        series = {"kinetic": c.kinetic, "rotational": c.rotational if self.spin else None,
                  "spring": c.spring, "gravitational": c.gravitational, "total": c.total}
        if self.dissipative:
            series["dissipated"] = c.dissipated
            series["total_plus_dissipated"] = c.balance
        parts = self.traj.energy_parts
        if parts is not None and len(parts) > 1:
            # DEM runs: each part's work, and what the tangential springs hold (the friction
            # account, and `dissipated`, include it until the springs let go).
            at = st.t
            def part(column: int) -> np.ndarray:
                return np.interp(at, parts[:, 0], parts[:, column])
            stored = part(4)
            series["dissipated_damping"] = part(1)
            series["dissipated_friction"] = part(2) - stored
            series["dissipated_rolling"] = part(3)
            series["tangential_spring"] = stored
        for key, values in series.items():
            if values is not None:
                # Rerun's automatic colours are a hash of the path: dissipated and gravitational
                # came out the same yellow.
                colour = ENERGY_COLOURS.get(key)
                self._static(f"/energy/{key}", rr.SeriesLines(colors=None if colour is None else [colour], names=[key]))
                self._send(f"/energy/{key}", rr.Scalars.columns(scalars=values), index)
        self._static("/momentum", rr.SeriesLines(names=[f"p.{a}" for a in _AXES[:model.dim]]))
        self._send("/momentum", rr.Scalars.columns(scalars=c.momentum), index)
        if c.angular_momentum is not None:
            names = ["L.z"] if model.dim == 2 else [f"L.{a}" for a in _AXES]
            self._static("/angular_momentum", rr.SeriesLines(names=names))
            self._send("/angular_momentum", rr.Scalars.columns(scalars=c.angular_momentum), index)
        times = self._residual_times()
        res = _frame_residuals(model, self.result.initial, self._states(times))
        at = rr.TimeColumn(TIMELINE, duration=times)
        self._send("/residuals/energy", rr.Scalars.columns(scalars=res.energy), at)
        if not model.n_walls:
            self._send("/residuals/momentum", rr.Scalars.columns(scalars=res.momentum), at)
            if model.dim > 1 and not model.periodic:  # (no torque balance in a periodic box)
                angular = rr.Scalars.columns(scalars=res.angular_momentum)
                self._send("/residuals/angular_momentum", angular, at)
