"""Seeded generator of hostile and careless command lines for `collide` (issue 14), and the
check every one of them must pass.

A case is a `collide run` (or, now and then, `collide batch`) command line: a built-in scene or
a generated TOML file (valid-looking, malformed, extreme), `--set` overrides of real and made-up
keys with values from ordinary to absurd, and options (`--dt`, `--integrator`, `--tol`, `--out`,
`--stride`). The contract (`check_outcome`): exit 0 with a JSON summary whose every number is
finite and nothing on stderr, or a non-zero exit with exactly one line `error: ...` on stderr,
never a traceback, a warning or an internal error.

Used by tests/test_fuzz.py (a fixed seed, a few hundred cases, in-process) and by
scripts/fuzz.py (thousands of cases, counts printed).
"""

from __future__ import annotations

import io
import json
import math
import os
import random
import signal
import sys
import tempfile
import traceback
from collections.abc import Iterator
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import dataclass
from pathlib import Path

BUILTINS = ["demo-1d", "demo-2d-stationary", "demo-2d-moving", "demo-bonus", "textbook-1d",
            "textbook-glancing", "textbook-unequal"]

# Value texts as a user could type them after `--set key=` (TOML, or not).
NUMBERS = ["0", "1", "-1", "0.5", "2", "3", "1500", "0.03", "-0.02", "1e-5", "1e-300", "1e300", "1e200",
           "-1e200", "1e30", "1e31", "-1e30", "1e-30", "1e-31", "5e-324", "nan", "-nan", "inf", "-inf",
           "1e308", "1.8e308", "1e400", "9" * 400, "-" + "9" * 400, "0x10", "1_000", "0o7", "+1.5", "2.0",
           "1e160", "-1e160", "1e15", "1e-15", "1e8", "1e12"]
OTHERS = ["true", "false", '"text"', '""', '"a\\nb"', "[1, 0]", "[1, 0, 0]", "[0.5, -0.5]", "[]", "[[1, 0]]",
          "[1e300, 1e300]", "[nan, 0]", "['a', 'b']", "1979-05-27", "07:32:00", "{a = 1}", "auto", "seed",
          "verlet", "kahan6", "solid", "shell", "", "[", "1e", "1..2", "=", "[1,", '"unterminated',
          "[" * 60 + "]" * 60, "[" * 1200 + "]" * 1200, "{" * 30, "a b", "ball1"]
KEYS = ["dim", "dt", "integrator", "duration", "tail", "tol", "gravity", "name", "description",
        "contact.k", "contact.mu", "contact.eps", "contact.lever", "contact.model",
        "body.ball1.mass", "body.ball1.radius", "body.ball1.inertia", "body.ball1.position",
        "body.ball1.velocity", "body.ball1.spin", "body.ball1.position.x", "body.ball1.position.y",
        "body.ball1.velocity.x", "body.ball1.velocity.y", "body.ball1.velocity.z", "body.ball2.mass",
        "body.ball2.radius", "body.ball2.velocity", "body.ball2.spin", "body.ball2.position.x",
        "body.ball2.velocity.x", "body.ball2.velocity.y", "wall.0.point", "wall.0.normal"]
BAD_KEYS = ["contact", "wall.3.point", "body.nobody.mass", "body.ball1", "body", "contact.bogus", "bogus",
            "a..b", ".", "body.ball1.velocity.w", "contact.k.x", "name.x", "", "body.ball1.mass.x"]
INTEGRATOR_OPTIONS = ["seed", "verlet", "yoshida4", "kahan6", "euler", ""]
# No step below 1e-6 s: a step that small is valid and costs minutes (demo-bonus at 1e-9 s: 1.3e7
# steps, 200 s), which is a cost, not a contract to fuzz.
DT_OPTIONS = ["auto", "1e-5", "1e-4", "1e-3", "0.1", "1", "0", "-1e-5", "nan", "inf", "1e-300", "abc", "1e-6"]
TOL_OPTIONS = ["1e-6", "1e-9", "1e-3", "1e-30", "0", "-1", "nan", "1e300", "x"]


def _sensible(rng: random.Random, key: str) -> str | None:
    """A value a careful user could set for `key` (None: no such key)."""
    last = key.rsplit(".", 1)[-1]
    if key == "contact.k":
        return repr(10 ** rng.uniform(2, 7))
    if key in ("contact.mu", "contact.eps"):
        return repr(rng.uniform(0, 1) if last == "mu" else 10 ** rng.uniform(-9, -3))
    if last == "mass":
        return repr(10 ** rng.uniform(-3, 1))
    if last == "radius":
        return repr(rng.uniform(0.005, 0.04))
    if last in ("x", "y", "z") and ".velocity." in key:
        return repr(rng.uniform(-3, 3))
    if last in ("x", "y", "z") and ".position." in key:
        return repr(rng.uniform(-0.02, 0.02))
    if last == "spin":
        return repr(rng.uniform(-10, 10))
    if key in ("duration", "tail"):
        return repr(10 ** rng.uniform(-3, 1))
    if key == "dt":
        return rng.choice(["auto", "1e-5", "1e-4", repr(10 ** rng.uniform(-5.5, -3))])
    if key == "integrator":
        return rng.choice(["seed", "verlet", "yoshida4", "kahan6"])
    if key == "tol":
        return repr(10 ** rng.uniform(-10, -3))
    return None


def _number(rng: random.Random) -> str:
    if rng.random() < 0.5:
        return rng.choice(NUMBERS)
    return repr(rng.choice([-1, 1]) * 10 ** rng.uniform(-8, 8))


def _value(rng: random.Random) -> str:
    return _number(rng) if rng.random() < 0.6 else rng.choice(OTHERS)


def _vector_text(rng: random.Random, dim: int) -> str:
    n = dim if rng.random() < 0.85 else rng.choice([0, 1, 2, 3, 4])
    if dim == 1 and n == 1 and rng.random() < 0.5:
        return _number(rng)
    return "[" + ", ".join(_number(rng) if rng.random() < 0.2 else repr(rng.uniform(-1, 1))
                           for _ in range(n)) + "]"


def generated_scene(rng: random.Random) -> str:
    """A scene file: mostly well-formed with sensible numbers, some of them replaced by extreme,
    wrong-typed or malformed ones; now and then not TOML at all."""
    roll = rng.random()
    if roll < 0.04:
        return rng.choice(["x = " + "[" * 1000 + "]" * 1000, "[[body]\nmass = 1", "dim = = 2", "\x00\x01",
                           "x = {" * 50, "", "dim = 2\n" * 3])
    dim = rng.choice([1, 2, 2, 3]) if rng.random() < 0.95 else rng.choice(["2.0", '"2"', "0", "4", "true"])
    d = dim if isinstance(dim, int) else 2
    lines = [f"dim = {dim}"]

    def maybe(text: str, sensible: str) -> str:
        return text if rng.random() < 0.05 else sensible

    if rng.random() < 0.5:
        lines.append("dt = " + maybe(_value(rng), rng.choice(["1e-5", "1e-4", '"auto"'])))
    if rng.random() < 0.3:
        lines.append("integrator = " + maybe(_value(rng), rng.choice(['"verlet"', '"kahan6"', '"seed"'])))
    if rng.random() < 0.25:
        lines.append(f"duration = {maybe(_value(rng), rng.choice(['0.5', '1.0', '2e-3']))}")
    if rng.random() < 0.1:
        lines.append(f"gravity = {_vector_text(rng, d)}")
    lines.append("[contact]")
    lines.append(f"k = {maybe(_number(rng), rng.choice(['1000.0', '1500.0', '1e5']))}")
    lines.append(f"mu = {maybe(_number(rng), rng.choice(['0.0', '0.3', '0.5']))}")
    if rng.random() < 0.1:
        lines.append(f"{rng.choice(['eps', 'lever', 'model', 'bogus'])} = {_value(rng)}")
    n_bodies = rng.choice([1, 2, 2, 2, 3, 4])
    x = 0.0
    for i in range(n_bodies):
        radius = rng.choice([0.03, 0.05, 0.1])
        x += 2.5 * radius + 0.05
        pos = [x] + [rng.uniform(-0.02, 0.02) for _ in range(d - 1)]
        vel = [rng.uniform(-2, 2) for _ in range(d)]
        lines.append("[[body]]")
        lines.append(f'name = "ball{i + 1}"')
        lines.append(f"mass = {maybe(_number(rng), rng.choice(['0.0254', '1.0', '0.17']))}")
        lines.append(f"radius = {maybe(_number(rng), repr(radius))}")
        position = repr(pos[0]) if d == 1 else repr(pos)
        velocity = repr(vel[0]) if d == 1 else repr(vel)
        lines.append(f"position = {maybe(_vector_text(rng, d), position)}")
        lines.append(f"velocity = {maybe(_vector_text(rng, d), velocity)}")
        if d > 1 and rng.random() < 0.3:
            lines.append(f"spin = {_number(rng) if d == 2 else _vector_text(rng, 3)}")
        if rng.random() < 0.05:
            lines.append(f"inertia = {_value(rng)}")
    if rng.random() < 0.15:
        lines.append("[[wall]]")
        lines.append(f"point = {_vector_text(rng, d) if rng.random() < 0.2 else repr([-1.0] + [0.0] * (d - 1))}")
        lines.append(f"normal = {_vector_text(rng, d) if rng.random() < 0.2 else repr([1.0] + [0.0] * (d - 1))}")
    return "\n".join(lines) + "\n"


@dataclass
class Case:
    """One command line; `scene_text` (if any) is written to `scene.toml` first."""

    number: int
    argv: list[str]
    scene_text: str | None = None


def cases(seed: int, count: int, folder: Path) -> Iterator[Case]:
    """`count` command lines from `seed` (the same seed, the same cases); files go in `folder`."""
    rng = random.Random(seed)
    for number in range(count):
        scene_text = None
        if rng.random() < 0.35:
            scene_text = generated_scene(rng)
            scene = str(folder / f"scene{number}.toml")
        else:
            scene = rng.choice(BUILTINS)
        sets: list[str] = []
        for _ in range(rng.choice([0, 1, 1, 2, 3])):
            key = rng.choice(KEYS) if rng.random() < 0.85 else rng.choice(BAD_KEYS)
            sensible = _sensible(rng, key)
            value = sensible if sensible is not None and rng.random() < 0.6 else _value(rng)
            sets += ["--set", f"{key}={value}" if rng.random() < 0.97 else key]
        options: list[str] = []
        if rng.random() < 0.2:
            options += ["--dt", rng.choice(DT_OPTIONS)]
        if rng.random() < 0.15:
            options += ["--integrator", rng.choice(INTEGRATOR_OPTIONS)]
        if rng.random() < 0.1:
            options += ["--tol", rng.choice(TOL_OPTIONS)]
        if rng.random() < 0.08:
            options += ["--dt", "auto", "--tol", rng.choice(TOL_OPTIONS)]
        if rng.random() < 0.92:
            if rng.random() < 0.03:
                options += [rng.choice(["--stride", "--bogus", "--csv-every"]), rng.choice(["1e3", "0", "-1", "x"])]
            if rng.random() < 0.06:
                out = rng.choice([str(folder / f"run{number}.rrd"), "/proc/x.rrd", str(folder), "/nonexistent/x.rrd"])
                options += ["--out", out]
            else:
                options.append("--no-record")
            argv = ["run", scene, *sets, *options, "--json"]
        else:
            sweep = f"{rng.choice(KEYS[:20])}={_number(rng)}:{_number(rng)}:{rng.choice(['1', '2', '3', '0', 'x'])}"
            argv = ["batch", scene, "--sweep", sweep, *sets, "--summary", str(folder / f"s{number}.csv"),
                    "--no-progress"]
        yield Case(number, argv, scene_text)


# ---------------------------------------------------------------------------------------------
# Running a case in-process and judging it


@dataclass
class Outcome:
    code: int
    stdout: str
    stderr: str
    hung: bool = False


class _Hang(BaseException):
    """Raised by the alarm: the case ran past its time limit (a hang, not a slow pass)."""


def run_case(case: Case, folder: Path, limit_s: int = 120) -> Outcome:
    """Run `collide ARGV` in this process (as the console script does) and capture everything."""
    from cli.main import main

    if case.scene_text is not None:
        (folder / f"scene{case.number}.toml").write_text(case.scene_text)
    out, err = io.StringIO(), io.StringIO()
    argv = sys.argv

    alarmed: list[bool] = []

    def alarm(signum: int, frame: object) -> None:
        alarmed.append(True)
        raise _Hang

    previous = signal.signal(signal.SIGALRM, alarm)
    signal.alarm(limit_s)
    code: int | str | None = 0
    hung = False
    # Rerun's Rust code logs to file descriptor 2 directly, past sys.stderr: capture that too.
    raw_err = tempfile.TemporaryFile()
    saved_fd = os.dup(2)
    os.dup2(raw_err.fileno(), 2)
    try:
        sys.argv = ["collide", *case.argv]
        with redirect_stdout(out), redirect_stderr(err):
            try:
                main()
            except SystemExit as exc:
                code = exc.code
            except Exception:  # escaped the CLI: the user would see this traceback
                err.write(traceback.format_exc())
                code = 1
    except _Hang:
        hung = True
        code = -1
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
        sys.argv = argv
        os.dup2(saved_fd, 2)
        os.close(saved_fd)
        raw_err.seek(0)
        err.write(raw_err.read().decode("utf-8", errors="replace"))
        raw_err.close()
    hung = hung or bool(alarmed)  # raised inside compiled code, the alarm can come back as another error
    if code is None:
        code = 0
    if not isinstance(code, int):
        err.write(str(code) + "\n")
        code = 1
    return Outcome(code, out.getvalue(), err.getvalue(), hung)


def _no_non_finite(text: str) -> None:
    raise ValueError(f"non-finite number {text} in the JSON summary")


def _finite_json(text: str) -> None:
    """Parse the JSON summary, refusing Infinity and NaN, and check every number is finite."""
    def walk(value: object) -> None:
        if isinstance(value, float) and not math.isfinite(value):
            raise ValueError(f"non-finite number {value} in the JSON summary")
        if isinstance(value, dict):
            for item in value.values():
                walk(item)
        elif isinstance(value, list):
            for item in value:
                walk(item)

    walk(json.loads(text, parse_constant=_no_non_finite))


def check_outcome(case: Case, outcome: Outcome) -> str | None:
    """None if the outcome keeps the contract, else what is wrong (one line)."""
    if outcome.hung:
        return "hung (ran past its time limit)"
    err_lines = outcome.stderr.splitlines()
    if "Traceback" in outcome.stderr:
        return "traceback on stderr"
    if "Warning" in outcome.stderr:
        return f"warning on stderr: {outcome.stderr.strip()[:200]}"
    if outcome.code == 0:
        if case.argv[0] == "run":
            if err_lines:
                return f"exit 0 with stderr: {outcome.stderr.strip()[:200]}"
            try:
                _finite_json(outcome.stdout)
            except ValueError as exc:
                return f"exit 0 with a bad JSON summary: {exc}"
        else:
            summary = Path(case.argv[case.argv.index("--summary") + 1])
            text = summary.read_text() if summary.exists() else ""
            if any(word in text.lower() for word in ("inf", "nan")):
                return "exit 0 with a non-finite number in the batch summary"
            if any(not line.startswith("note: ") for line in err_lines):
                return f"exit 0 with stderr: {outcome.stderr.strip()[:200]}"
        return None
    if len(err_lines) != 1:
        return f"exit {outcome.code} with {len(err_lines)} lines on stderr: {outcome.stderr.strip()[:300]}"
    if not err_lines[0].startswith("error: "):
        return f"exit {outcome.code}, stderr not 'error: ...': {err_lines[0][:200]}"
    if "internal error" in err_lines[0]:
        return f"internal error: {err_lines[0][:300]}"
    if "overflowed float64 during the run" in err_lines[0]:  # the CLI's last net, not a named guard
        return f"refused only by the CLI's overflow net: {err_lines[0][:300]}"
    if case.argv[0] == "run" and outcome.stdout.strip():
        return f"exit {outcome.code} with output on stdout: {outcome.stdout.strip()[:200]}"
    return None
