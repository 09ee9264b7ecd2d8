"""Which controls a scene needs, their ranges, how typed values are read, and how the values
become a scene.

Pure Python (no viser): the GUI layer builds one slider and one text box per `Param`, reads the
values back in display units, and calls `build_scene`. Slider ranges are derived from the
scene's own values, so a slider starts at the scene's setting and spans a physically sensible
neighbourhood. A typed value is read exactly (`read_typed`: `1e-7` is 1e-7) or refused with a
one-line reason, never changed into another number; a valid value outside the slider's range
widens the range. A combination the core refuses (overlap at the start, a contact too soft)
surfaces as the core's one-line `SceneError` or `RunError`.

Contact parameters come from one table (`CONTACT_PARAMS`), each with the condition under which
the scene uses it: a contact law parameter such as `contact.restitution` is one more row.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from collide.scene import INTEGRATORS, Scene, SceneError, parse_scene, set_path

DT_CHOICES = tuple(m * 10.0**e for e in range(-8, -2) for m in (1.0, 2.0, 5.0))
TOL_CHOICES = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)
AUTO = "auto"
DEM_TOL = 1e-3  # the viewer's least tol for a run it moves to the DEM kernel
MAX_BALLS = 10  # "more balls" stops here: beyond two bodies each step uses the slower numpy path


class TypedValueError(ValueError):
    """A typed value that cannot be used as typed (not a number, not finite, not allowed)."""


@dataclass(frozen=True)
class Param:
    """One scalar control, in display units (`display = SI * scale`).

    `key` is the scene key it sets: `contact.k`, `body.ball1.mass`, or a vector component
    `body.ball1.velocity.y` (`component` is then 0, 1 or 2 and `key` names the vector).
    [lo, hi] is the slider's range; `positive` / `nonneg` what the scene accepts at all.
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
    hint: str = ""
    positive: bool = False
    nonneg: bool = False
    unused: str = ""  # why the parameter changes nothing in this scene (its control is disabled)

    @property
    def ident(self) -> str:
        """Unique name of the control (the key, with the component letter for vectors)."""
        return self.key if self.component is None else f"{self.key}.{'xyz'[self.component]}"

    @property
    def title(self) -> str:
        """The label with its unit, as shown beside the control."""
        return f"{self.label} ({self.unit})" if self.unit else self.label

    def problem(self, x: float) -> str | None:
        """Why the scene cannot take display value x, or None."""
        if not math.isfinite(x):
            return "must be finite"
        if self.positive and x <= 0:
            return "must be positive"
        if self.nonneg and x < 0:
            return "must not be negative"
        return None

    def widened(self, x: float) -> Param:
        """This control with its slider range grown to include x (a typed value)."""
        if self.lo <= x <= self.hi:
            return self
        if self.positive and x > 0:
            lo, hi = min(self.lo, x / 10), max(self.hi, x * 10)
        else:
            span = max(self.hi - self.lo, abs(x))
            lo, hi = min(self.lo, x - 0.25 * span), max(self.hi, x + 0.25 * span)
            if self.nonneg:
                lo = max(lo, 0.0)
        lo, hi, step = _range(x, lo, hi, max(round((self.hi - self.lo) / self.step), 100))
        return replace(self, lo=lo, hi=hi, step=step)


def read_typed(text: str, what: str) -> float:
    """A number typed by the user, read exactly as typed: plain or scientific notation
    ('0.02', '-3', '1e-7', '2.5E9'). Anything else raises `TypedValueError` naming `what`;
    nothing is ever rounded, clamped or reinterpreted."""
    cleaned = text.strip().replace("\u2212", "-")  # a typographic minus is still a minus
    if not cleaned:
        raise TypedValueError(f"{what}: empty; not applied")
    if "," in cleaned:
        raise TypedValueError(f"{what} = '{text.strip()}': use a point for decimals, not a comma; not applied")
    if "_" in cleaned:
        raise TypedValueError(f"{what} = '{text.strip()}' is not a plain number; not applied")
    try:
        x = float(cleaned)
    except ValueError:
        raise TypedValueError(f"{what} = '{text.strip()}' is not a number (write e.g. 0.02 or 1e-7); "
                              "not applied") from None
    if not math.isfinite(x):
        raise TypedValueError(f"{what} = '{text.strip()}' is not finite; not applied")
    return x


def format_value(x: float) -> str:
    """A value as a text box shows it: short, and read back to the same float."""
    for digits in (6, 9, 12, 17):
        text = f"{x:.{digits}g}"
        if float(text) == x:
            return text
    return repr(x)


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
        """The parameters' groups in order of first appearance (a dict: a list's `in` made this
        quadratic, over a second for a 1 000-body pile)."""
        return list(dict.fromkeys(p.group for p in self.params))

    def defaults(self) -> dict[str, float]:
        return {p.ident: p.value for p in self.params}

    def replace_param(self, param: Param) -> None:
        self.params = [param if p.ident == param.ident else p for p in self.params]


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


def _range(value: float, lo: float, hi: float, divisions: int = 1000) -> tuple[float, float, float]:
    step = _nice_step(hi - lo, divisions)
    lo, hi = math.floor(lo / step) * step, math.ceil(hi / step) * step
    return round(lo, 12), round(hi, 12), step


def format_dt(dt: float) -> str:
    return f"{dt:.0e} s".replace("e-0", "e-")


def length_unit(scene: Scene) -> tuple[str, float]:
    """Millimetres for table-top scenes, metres for larger ones."""
    bodies = list(scene.bodies)  # each pass over scene.bodies builds the bodies from its columns
    extent = max([b.radius for b in bodies] + [abs(c) for b in bodies for c in b.position])
    return ("mm", 1e3) if extent < 2.0 else ("m", 1.0)


@dataclass(frozen=True)
class ContactParam:
    """A row of the contact table: which `[contact]` key, how it is shown, when it applies,
    and its slider range from the scene's value."""

    name: str
    label: str
    unit: str
    applies: Callable[[Scene], bool]
    span: Callable[[float], tuple[float, float, float]]
    hint: str
    positive: bool = False
    nonneg: bool = False


def _k_span(k: float) -> tuple[float, float, float]:
    return _range(k, k / 10, k * 10)


CONTACT_PARAMS: tuple[ContactParam, ...] = (
    ContactParam("k", "k", "N/m", lambda s: s.contact.model == "linear", _k_span,
                 "each sphere's spring constant (the report measured 1500 +- 30 N/m)", positive=True),
    ContactParam("mu", "mu", "", lambda s: s.dim > 1, lambda x: (0.0, max(2.0, 2 * x), 0.01),
                 "Coulomb friction coefficient", nonneg=True),
    ContactParam("eps", "eps", "m/s", lambda s: s.dim > 1, lambda x: (0.0, max(0.1, 10 * x), 1e-7),
                 "friction dead band: slip below it feels no friction", nonneg=True),
    # The elasticity slider (docs/design.md section 9), for every scene: below 1 the run takes the
    # engine that runs the dashpot (`build_scene`). Below 0.05 a contact is nearly plastic and
    # lasts long: the slider starts there unless the scene is perfectly inelastic (0).
    ContactParam("restitution", "restitution", "", lambda s: hasattr(s.contact, "restitution"),
                 lambda x: (0.0 if x < 0.05 else 0.05, 1.0, 0.01),
                 "coefficient of restitution: 1 elastic, smaller loses energy, 0 perfectly inelastic", nonneg=True),
    # The laws beyond the report's, where the scene uses them (docs/design.md section 9).
    ContactParam("youngs_modulus", "E", "Pa", lambda s: s.contact.model == "hertz", _k_span,
                 "Young's modulus of the Hertz contact", positive=True),
    ContactParam("tangential_stiffness_ratio", "k_t / k_n", "", lambda s: s.contact.tangential == "spring",
                 lambda x: _range(x, 0.05, max(1.0, x)),
                 "tangential spring stiffness over the normal stiffness; until moved, each pair takes Mindlin's "
                 "from its materials (Hertz) or 2/7 (linear)", positive=True),
    ContactParam("rolling_friction", "mu_r", "", lambda s: s.dim > 1 and s.has_rolling,
                 lambda x: (0.0, max(0.2, 2 * x), 0.001),
                 "rolling resistance: a torque mu_r R* F_n against the rolling", nonneg=True),
)


def _contact_value(contact, name: str) -> float | None:
    """[contact]'s own value for a row (None: the scene takes it from its materials only); the
    tangential ratio's default is the law's (2/7 linear, Mindlin's for Hertz)."""
    if name == "tangential_stiffness_ratio":
        return contact.stiffness_ratio
    value = getattr(contact, name)
    return None if value is None else float(value)


def scene_controls(scene: Scene) -> Controls:
    """The controls a scene uses: per body mass, radius, position, velocity (and spin where
    bodies can rotate); the contact table's rows that apply; gravity if set."""
    params: list[Param] = []
    lunit, lscale = length_unit(scene)
    dim = scene.dim
    bodies = list(scene.bodies)  # each pass over scene.bodies builds the bodies from its columns
    r_max = max(b.radius for b in bodies)
    r_min = min(b.radius for b in bodies)
    v_max = max([abs(c) for b in bodies for c in b.velocity] + [0.5])
    w_max = max([abs(c) for b in bodies for c in b.spin] + [0.0])
    spans = [max(b.position[c] for b in bodies) - min(b.position[c] for b in bodies)
             for c in range(dim)]
    for body in bodies:
        base = f"body.{body.name}"
        munit, mscale = ("g", 1e3) if body.mass < 1.0 else ("kg", 1.0)
        m = body.mass * mscale
        params.append(Param(f"{base}.mass", "mass", body.name, munit, mscale,
                            *_range(m, m / 10, m * 10), value=m, positive=True))
        r = body.radius * lscale
        params.append(Param(f"{base}.radius", "radius", body.name, lunit, lscale,
                            *_range(r, r / 4, r * 3), value=r, positive=True))
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
    for row in CONTACT_PARAMS:
        if not row.applies(scene):
            continue
        own = _own_values(scene, row.name)
        x = _contact_value(scene.contact, row.name)
        if x is not None:
            lo, hi, step = row.span(x)
            unused = ""
            if own and not default_used(scene, row.name):
                unused = (f"[contact] {row.name} reaches no contact here: the materials and pairs set every "
                          f"contact's own ({', '.join(label for label, _, _ in own)}: their sliders below)")
            params.append(Param(f"contact.{row.name}", row.label, "contact", row.unit, 1.0, lo, hi, step, x,
                                hint=row.hint, positive=row.positive, nonneg=row.nonneg, unused=unused))
        # A material's or a pair's own value: a slider of its own (break-3d's balls bounce at
        # 0.95 off each other and 0.5 off the cloth).
        for label, key, value in own:
            lo, hi, step = row.span(value)
            params.append(Param(key, f"{row.label} ({label})", "contact", row.unit, 1.0, lo, hi, step, value,
                                hint=f"{row.hint}; {label} only", positive=row.positive, nonneg=row.nonneg))
    if scene.gravity is not None:
        for c in range(dim):
            g = scene.gravity[c]
            params.append(Param("gravity", f"gravity {'xyz'[c]}" if dim > 1 else "gravity", "contact",
                                "m/s²", 1.0, min(-30.0, g), max(30.0, g), 0.01, g, component=c))
    dt_choices = [AUTO] + [format_dt(d) for d in DT_CHOICES]
    if scene.dt != AUTO and format_dt(float(scene.dt)) not in dt_choices:
        dt_choices.append(format_dt(float(scene.dt)))
    settings = Settings(scene.integrator, scene.dt, scene.tol)
    tol_choices = [f"{t:.0e}" for t in TOL_CHOICES]
    if f"{scene.tol:.0e}" not in tol_choices:
        tol_choices.append(f"{scene.tol:.0e}")
    return Controls(scene, params, settings, dt_choices, tol_choices)


def _own_values(scene: Scene, name: str) -> list[tuple[str, str, float]]:
    """(label, key, value) of every material and pair table that gives its own `name` (mu,
    restitution): keys `material.NAME.FIELD` and `pair.INDEX.FIELD` (the pair tables in order)."""
    out = [(m.name, f"material.{m.name}.{name}", float(getattr(m, name))) for m in scene.materials
           if hasattr(m, name) and getattr(m, name) is not None]
    out += [("–".join(p.materials), f"pair.{k}.{name}", float(getattr(p, name))) for k, p in enumerate(scene.pairs)
            if hasattr(p, name) and getattr(p, name) is not None]
    return out


def default_used(scene: Scene, name: str) -> bool:
    """Whether some contact the scene can have takes [contact]'s `name` (mu, restitution): a
    body without a material, a sphere on a wall whose material gives none, or a pair of
    materials with no pair table where either material gives none (the mixing rule takes
    [contact]'s for it)."""
    materials = {m.name: m for m in scene.materials}

    def own(material: str | None) -> bool:
        return material is not None and getattr(materials.get(material), name, None) is not None

    used = [b.material for b in scene.bodies]
    if any(m is None for m in used):
        return True
    if scene.walls and not all(own(m) for m in used):
        return True
    tables = {frozenset(p.materials) for p in scene.pairs if getattr(p, name, None) is not None}
    count = {m: used.count(m) for m in set(used)}
    kinds = sorted(count)
    for x, a in enumerate(kinds):
        for b in kinds[x:]:
            if a == b and count[a] < 2:
                continue  # one body of a material: no pair of it
            if frozenset((a, b)) not in tables and not (own(a) and own(b)):
                return True
    return False


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
    # DEM's tol is 1 / steps per contact (the kernel takes at least 50): the built-in pile asks 4e-2.
    top = 0.1 if integrator == "dem" else 1e-2
    if not (1e-12 <= tol <= top):
        raise SceneError(f"tol: {tol!r} is outside the safe range 1e-12 .. {top:g}")
    return Settings(integrator, dt, tol)


def build_scene(controls: Controls, values: dict[str, float], settings: Settings) -> Scene:
    """The scene with the controls' values (display units) applied, ready to view.

    Raises `SceneError` for a value the scene cannot take or a combination the core refuses
    (e.g. spheres overlapping at the start), naming the control.
    """
    raw = copy.deepcopy(controls.scene.source)
    # Each body's table found by name once: set_path alone looks it up by scanning every body,
    # (bodies x parameters per body) for each run, seconds for 1 000 spheres.
    tables = {t.get("name"): {"body": [t]} for t in raw.get("body", []) if isinstance(t, dict)} \
        if isinstance(raw.get("body"), list) else {}

    def put(key: str, value: float | list[float]) -> None:
        parts = key.split(".")
        if parts[0] == "pair":  # pair tables are found by their order (they have no name)
            raw["pair"][int(parts[1])][parts[2]] = value
            return
        set_path(tables.get(parts[1], raw) if parts[0] == "body" else raw, key, value)

    vectors: dict[str, list[float]] = {}
    for param in controls.params:
        display = float(values.get(param.ident, param.value))
        problem = param.problem(display)
        if problem:
            where = f"{param.group} {param.title}" if param.group != "contact" else param.title
            raise SceneError(f"{where} = {display:g}: {problem}")
        si = display / param.scale
        if param.component is None:
            if display != param.value:  # an unmoved control leaves the scene's own value (a law's default too)
                put(param.key, si)
        else:
            vectors.setdefault(param.key, [0.0] * controls.scene.dim)[param.component] = si
    for key, vector in vectors.items():
        put(key, vector[0] if controls.scene.dim == 1 and key != "gravity" else vector)
    raw["integrator"] = settings.integrator
    raw["dt"] = settings.dt
    raw["tol"] = settings.tol
    if settings.integrator != "dem":
        # A law beyond the report's (restitution below 1 from the slider, Hertz...): the event
        # engine where it runs it at full order (its steps from tol: dt auto), else the DEM
        # kernel rather than a refusal, at 1 000 steps a contact at most (DEM's tol is 1/steps).
        probe = parse_scene({key: value for key, value in raw.items() if key not in ("integrator", "dt", "tol")},
                            controls.scene.name)
        if probe.needs_dem:
            raw["dt"] = AUTO
            if probe.integrator == "dem":
                raw["integrator"] = "dem"
                raw["tol"] = max(settings.tol, DEM_TOL)
    return for_viewing(parse_scene(raw, controls.scene.name))


def values_of(scene: Scene, controls: Controls) -> dict[str, float]:
    """Display values of a scene's parameters under `controls` (e.g. after loading a recording)."""
    out = {}
    bodies = {body.name: body for body in scene.bodies}
    for param in controls.params:
        parts = param.key.split(".")
        if parts[0] == "body":
            body = bodies[parts[1]]
            value = getattr(body, parts[2])
        elif parts[0] == "material":
            value = getattr(next(m for m in scene.materials if m.name == parts[1]), parts[2])
        elif parts[0] == "pair":
            value = getattr(scene.pairs[int(parts[1])], parts[2])
        elif parts[0] == "contact":
            value = _contact_value(scene.contact, parts[1])  # as `scene_controls` shows it
        else:
            value = getattr(scene, parts[0])
        if isinstance(value, tuple):
            value = value[param.component or 0]
        out[param.ident] = float(value) * param.scale
    return out


# ---------------------------------------------------------------------------------------------
# What the viewer runs: the scene with a tail long enough to see the outcome


def approach_time(scene: Scene) -> float | None:
    """Time until the first contact begins, from the start state in straight-line motion (an
    estimate: gravity is left out); None when nothing is heading for a contact."""
    best = math.inf
    bodies = scene.bodies
    for i, a in enumerate(bodies):
        for b in bodies[i + 1:]:
            d = [q - p for p, q in zip(a.position, b.position)]
            u = [q - p for p, q in zip(a.velocity, b.velocity)]
            reach = a.radius + b.radius
            aa = sum(x * x for x in u)
            bb = 2 * sum(x * y for x, y in zip(d, u))
            cc = sum(x * x for x in d) - reach * reach
            disc = bb * bb - 4 * aa * cc
            if aa > 0 and bb < 0 and disc >= 0:
                best = min(best, max(0.0, (-bb - math.sqrt(disc)) / (2 * aa)))
        for wall in scene.walls:
            height = sum((p - q) * n for p, q, n in zip(a.position, wall.point, wall.normal)) - a.radius
            rate = sum(v * n for v, n in zip(a.velocity, wall.normal))
            if rate < 0:
                best = min(best, max(0.0, height / -rate))
    return best if math.isfinite(best) else None


def for_viewing(scene: Scene) -> Scene:
    """The scene as the viewer runs it: when it sets neither `duration` nor `tail`, the run goes
    on after the last separation for as long as the bodies took to meet, so the outcome (the
    textbook's 37 degree split) is seen, not cut off a few milliseconds after the contact.
    Free flight is exact and not stepped, so the longer tail costs nothing."""
    if scene.duration is not None or scene.tail is not None:
        return scene
    t = approach_time(scene)
    if t is None or t <= 0:
        return scene
    raw = copy.deepcopy(scene.source)
    raw["tail"] = t
    return parse_scene(raw, scene.name)


# ---------------------------------------------------------------------------------------------
# More balls, fewer balls (2D scenes, as in PhET's Collision Lab)


def _free_name(scene: Scene) -> str:
    names = {b.name for b in scene.bodies}
    n = len(scene.bodies) + 1
    while f"ball{n}" in names:
        n += 1
    return f"ball{n}"


def _first_meeting(scene: Scene) -> float | None:
    """When two of the scene's balls first touch in free flight (s), or None if no two ever do.
    Relative motion: gravity, the same for all, drops out."""
    best = None
    bodies = scene.bodies
    for a in range(len(bodies)):
        for b in range(a + 1, len(bodies)):
            d = np.subtract(bodies[b].position, bodies[a].position)
            u = np.subtract(bodies[b].velocity, bodies[a].velocity)
            reach = bodies[a].radius + bodies[b].radius
            uu, du = float(u @ u), float(d @ u)
            disc = du * du - uu * (float(d @ d) - reach * reach)
            if uu <= 0 or du >= 0 or disc < 0:
                continue
            t = (-du - math.sqrt(disc)) / uu
            if t >= 0 and (best is None or t < best):
                best = t
    return best


def add_ball(scene: Scene) -> Scene:
    """The scene with one more ball like the last one, aimed to take part: it reaches the
    balls' centre of mass when the first two of them meet (coming in across their line of
    approach), from far enough out not to overlap any ball at the start; without a meeting, it is
    placed behind the leftmost ball and sent towards the others. Raises SceneError when it
    cannot be added."""
    if scene.dim != 2:
        raise SceneError("more balls: only for 2D scenes")
    if len(scene.bodies) >= MAX_BALLS:
        raise SceneError(f"more balls: at most {MAX_BALLS} here (a bigger scene goes in a .toml file)")
    raw = copy.deepcopy(scene.source)
    template = scene.bodies[-1]
    r = template.radius
    speed = max([math.hypot(*b.velocity) for b in scene.bodies] + [0.0]) or 1.0
    body = {"name": _free_name(scene), "mass": template.mass, "radius": r, "velocity": [speed, 0.0]}
    if template.spin and scene.has_spin:
        body["spin"] = 0.0
    raw.setdefault("body", []).append(body)
    meet = _first_meeting(scene)
    if meet is None:
        left = min(scene.bodies, key=lambda b: b.position[0] - b.radius)
        n = len(scene.bodies)
        # Staggered across the line of approach, so a new ball hits at an angle, not head-on.
        start = np.array([left.position[0] - left.radius - 3 * r, left.position[1] + (0.6 if n % 2 else -0.6) * r])
        places = [(start - [2 * r * k, 0.0], np.array([speed, 0.0])) for k in range(20)]
    else:
        mass = np.array([b.mass for b in scene.bodies])
        com = mass @ np.array([b.position for b in scene.bodies]) / mass.sum()
        v_com = mass @ np.array([b.velocity for b in scene.bodies]) / mass.sum()
        fastest = max(scene.bodies, key=lambda b: math.hypot(*np.subtract(b.velocity, v_com)))
        along = np.subtract(fastest.velocity, v_com)
        along = along / np.linalg.norm(along) if np.linalg.norm(along) > 0 else np.array([1.0, 0.0])
        across = np.array([-along[1], along[0]])
        # Later arrivals start further out: the first place clear of every ball is taken.
        places = []
        for k in range(20):
            t = meet + k * 2 * r / speed
            places.append((com + v_com * t - across * speed * t, v_com + across * speed))
    for position, velocity in places:
        body["position"], body["velocity"] = [float(x) for x in position], [float(x) for x in velocity]
        try:
            return parse_scene(raw, scene.name)
        except SceneError as exc:
            if "overlaps" not in str(exc):
                raise
    raise SceneError("more balls: no free place found for another ball")


def remove_ball(scene: Scene) -> Scene:
    """The scene without its last ball (at least two stay)."""
    if len(scene.bodies) <= 2:
        raise SceneError("fewer balls: a collision needs at least two")
    raw = copy.deepcopy(scene.source)
    name = scene.bodies[-1].name
    raw["body"] = [b for b in raw["body"] if b.get("name", "") != name]
    return parse_scene(raw, scene.name)
