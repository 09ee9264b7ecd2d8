"""Which controls a scene needs, their safe ranges, and how their values become a scene.

Pure Python (no viser): the GUI layer builds one slider per `Param`, reads the values back in
display units, and calls `build_scene`. Ranges are derived from the scene's own values, so a
slider always starts at the scene's setting and spans a physically sensible neighbourhood.
A value outside a range is clamped (`Param.clamp` says so); a combination the core refuses
(overlap at the start, a contact too soft) surfaces as the core's one-line `SceneError` or
`RunError`.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field

from collide.scene import INTEGRATORS, Scene, SceneError, parse_scene, set_path

DT_CHOICES = tuple(m * 10.0**e for e in range(-8, -2) for m in (1.0, 2.0, 5.0))
TOL_CHOICES = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)
AUTO = "auto"


@dataclass(frozen=True)
class Param:
    """One scalar control, in display units (`display = SI * scale`).

    `key` is the scene key it sets: `contact.k`, `body.ball1.mass`, or a vector component
    `body.ball1.velocity.y` (`component` is then 0, 1 or 2 and `key` names the vector).
    """

    key: str
    label: str
    group: str
    unit: str
    scale: float
    lo: float
    hi: float
    step: float
    value: float
    component: int | None = None
    slider: bool = True
    hint: str = ""

    @property
    def ident(self) -> str:
        """Unique name of the control (the key, with the component letter for vectors)."""
        return self.key if self.component is None else f"{self.key}.{'xyz'[self.component]}"

    def clamp(self, display: float) -> tuple[float, str | None]:
        """The value inside [lo, hi] and a message when it had to be moved (or was not a number)."""
        try:
            x = float(display)
        except (TypeError, ValueError):
            return self.value, f"{self.label}: not a number; reset to {self.value:g} {self.unit}".strip()
        if not math.isfinite(x):
            return self.value, f"{self.label}: not finite; reset to {self.value:g} {self.unit}".strip()
        if x < self.lo or x > self.hi:
            clamped = min(max(x, self.lo), self.hi)
            return clamped, (f"{self.label} = {x:g} is outside the safe range "
                             f"[{self.lo:g}, {self.hi:g}] {self.unit}; clamped to {clamped:g}").strip()
        return x, None


@dataclass(frozen=True)
class Settings:
    """Run settings chosen in the GUI: integrator, dt (seconds or "auto"), tol (for auto)."""

    integrator: str
    dt: float | str
    tol: float

    def label(self) -> str:
        dt = AUTO if self.dt == AUTO else f"{self.dt:.3g} s"
        return f"{self.integrator}, dt {dt}" + (f" (tol {self.tol:.0e})" if self.dt == AUTO else "")


@dataclass
class Controls:
    """Every control a scene needs, in the order the GUI shows them."""

    scene: Scene
    params: list[Param]
    settings: Settings
    dt_choices: list[str] = field(default_factory=list)
    tol_choices: list[str] = field(default_factory=list)

    def by_ident(self) -> dict[str, Param]:
        return {p.ident: p for p in self.params}

    def groups(self) -> list[str]:
        seen: list[str] = []
        for p in self.params:
            if p.group not in seen:
                seen.append(p.group)
        return seen

    def defaults(self) -> dict[str, float]:
        return {p.ident: p.value for p in self.params}


def _nice_step(span: float, divisions: int = 1000) -> float:
    """A round step (1, 2 or 5 times a power of ten) near span / divisions."""
    raw = span / divisions
    if not raw > 0:
        return 1.0
    exp = math.floor(math.log10(raw))
    for m in (1.0, 2.0, 5.0, 10.0):
        if m * 10.0**exp >= raw:
            return m * 10.0**exp
    return 10.0 ** (exp + 1)


def _snap(x: float, step: float) -> float:
    """x rounded to a multiple of step (keeps slider ends on the step grid)."""
    return round(round(x / step) * step, 12)


def _range(value: float, lo: float, hi: float, divisions: int = 1000) -> tuple[float, float, float]:
    step = _nice_step(hi - lo, divisions)
    lo, hi = math.floor(lo / step) * step, math.ceil(hi / step) * step
    return round(lo, 12), round(hi, 12), step


def format_dt(dt: float) -> str:
    return f"{dt:.0e} s".replace("e-0", "e-")


def length_unit(scene: Scene) -> tuple[str, float]:
    """Millimetres for table-top scenes, metres for larger ones."""
    extent = max([b.radius for b in scene.bodies] +
                 [abs(c) for b in scene.bodies for c in b.position])
    return ("mm", 1e3) if extent < 2.0 else ("m", 1.0)


def scene_controls(scene: Scene) -> Controls:
    """The controls a scene uses: per body mass, radius, position, velocity (and spin where
    bodies can rotate); contact k (and mu, eps where friction can act); gravity if set."""
    params: list[Param] = []
    lunit, lscale = length_unit(scene)
    dim = scene.dim
    r_max = max(b.radius for b in scene.bodies)
    r_min = min(b.radius for b in scene.bodies)
    v_max = max([abs(c) for b in scene.bodies for c in b.velocity] + [0.5])
    w_max = max([abs(c) for b in scene.bodies for c in b.spin] + [0.0])
    spans = [max(b.position[c] for b in scene.bodies) - min(b.position[c] for b in scene.bodies)
             for c in range(dim)]
    for body in scene.bodies:
        base = f"body.{body.name}"
        munit, mscale = ("g", 1e3) if body.mass < 1.0 else ("kg", 1.0)
        m = body.mass * mscale
        params.append(Param(f"{base}.mass", "mass", body.name, munit, mscale,
                            *_range(m, m / 10, m * 10), value=m))
        r = body.radius * lscale
        params.append(Param(f"{base}.radius", "radius", body.name, lunit, lscale,
                            *_range(r, r / 4, r * 3), value=r))
        for c in range(dim):
            p = body.position[c] * lscale
            # Along the line of approach the bodies travel the scene's width; across it, a few
            # radii cover every impact parameter from head-on to a miss.
            half = max(spans[c], 3 * r_max) * lscale
            lo, hi, step = _range(p, p - half, p + half, 2000)
            params.append(Param(f"{base}.position", f"position {'xyz'[c]}" if dim > 1 else "position",
                                body.name, lunit, lscale, lo, hi, step, p, component=c))
        for c in range(dim):
            v = body.velocity[c]
            lo, hi, step = _range(v, -2.5 * v_max, 2.5 * v_max)
            params.append(Param(f"{base}.velocity", f"velocity {'xyz'[c]}" if dim > 1 else "velocity",
                                body.name, "m/s", 1.0, lo, hi, step, v, component=c))
        if dim == 2:
            w_lim = max(2 * w_max, v_max / r_min, 1.0)
            lo, hi, step = _range(body.spin[0], -w_lim, w_lim)
            params.append(Param(f"{base}.spin", "spin", body.name, "rad/s", 1.0, lo, hi, step,
                                body.spin[0], hint="angular velocity about z"))
        elif dim == 3:
            w_lim = max(2 * w_max, v_max / r_min, 1.0)
            for c in range(3):
                lo, hi, step = _range(body.spin[c], -w_lim, w_lim)
                params.append(Param(f"{base}.spin", f"spin {'xyz'[c]}", body.name, "rad/s", 1.0,
                                    lo, hi, step, body.spin[c], component=c))
    contact = scene.contact
    k = contact.k
    params.append(Param("contact.k", "k", "contact", "N/m", 1.0, *_range(k, k / 10, k * 10), value=k,
                        hint="each sphere's spring constant (the report measured 1500 +- 30 N/m)"))
    if dim > 1:
        params.append(Param("contact.mu", "mu", "contact", "", 1.0, 0.0, 2.0, 0.01, contact.mu,
                            hint="Coulomb friction coefficient"))
        params.append(Param("contact.eps", "eps", "contact", "m/s", 1.0, 0.0, 0.1, 1e-7, contact.eps,
                            slider=False, hint="friction dead band: slip below it feels no friction"))
    if scene.gravity is not None:
        for c in range(dim):
            g = scene.gravity[c]
            params.append(Param("gravity", f"gravity {'xyz'[c]}" if dim > 1 else "gravity", "contact",
                                "m/s^2", 1.0, -30.0, 30.0, 0.01, g, component=c))
    dt_choices = [AUTO] + [format_dt(d) for d in DT_CHOICES]
    if scene.dt != AUTO and format_dt(float(scene.dt)) not in dt_choices:
        dt_choices.append(format_dt(float(scene.dt)))
    settings = Settings(scene.integrator, scene.dt, scene.tol)
    tol_choices = [f"{t:.0e}" for t in TOL_CHOICES]
    if f"{scene.tol:.0e}" not in tol_choices:
        tol_choices.append(f"{scene.tol:.0e}")
    return Controls(scene, params, settings, dt_choices, tol_choices)


def parse_dt_choice(text: str) -> float | str:
    """'auto' or a number of seconds from a dt dropdown label ('1e-5 s')."""
    text = text.strip()
    if text == AUTO:
        return AUTO
    value = float(text.removesuffix("s").strip())
    if not (value > 0 and math.isfinite(value)):
        raise SceneError(f"dt: must be positive, got {text!r}")
    return value


def dt_choice(dt: float | str) -> str:
    return AUTO if dt == AUTO else format_dt(float(dt))


def check_settings(integrator: str, dt: float | str, tol: float) -> Settings:
    """Validate run settings from the GUI (the dropdowns only offer valid ones; a stale or
    hand-made value still gets a clear message)."""
    if integrator not in INTEGRATORS:
        raise SceneError(f"integrator: unknown '{integrator}' (choose from {', '.join(INTEGRATORS)})")
    if dt != AUTO and not (isinstance(dt, float) and 1e-10 <= dt <= 1e-2):
        raise SceneError(f"dt: {dt!r} is outside the safe range 1e-10 .. 1e-2 s")
    if not (1e-12 <= tol <= 1e-2):
        raise SceneError(f"tol: {tol!r} is outside the safe range 1e-12 .. 1e-2")
    return Settings(integrator, dt, tol)


def build_scene(controls: Controls, values: dict[str, float], settings: Settings) -> tuple[Scene, list[str]]:
    """The scene with the controls' values (display units) applied; clamps out-of-range values.

    Returns the scene and the clamping messages. Raises `SceneError` for combinations the
    core refuses (e.g. spheres overlapping at the start).
    """
    raw = copy.deepcopy(controls.scene.source)
    notes: list[str] = []
    vectors: dict[str, list[float]] = {}
    for param in controls.params:
        display = values.get(param.ident, param.value)
        display, note = param.clamp(display)
        if note:
            notes.append(f"{param.group} {note}" if param.group != "contact" else note)
        si = display / param.scale
        if param.component is None:
            set_path(raw, param.key, si)
        else:
            vectors.setdefault(param.key, [0.0] * controls.scene.dim)[param.component] = si
    for key, vector in vectors.items():
        set_path(raw, key, vector[0] if controls.scene.dim == 1 and key != "gravity" else vector)
    raw["integrator"] = settings.integrator
    raw["dt"] = settings.dt
    raw["tol"] = settings.tol
    return parse_scene(raw, controls.scene.name), notes


def values_of(scene: Scene, controls: Controls) -> dict[str, float]:
    """Display values of a scene's parameters under `controls` (e.g. after loading a recording)."""
    out = {}
    for param in controls.params:
        parts = param.key.split(".")
        if parts[0] == "body":
            body = scene.bodies[scene.body_index(parts[1])]
            value = getattr(body, parts[2])
        elif parts[0] == "contact":
            value = getattr(scene.contact, parts[1])
        else:
            value = getattr(scene, parts[0])
        if isinstance(value, tuple):
            value = value[param.component or 0]
        out[param.ident] = float(value) * param.scale
    return out
