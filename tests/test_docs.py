"""The documentation is part of the product: README.md and docs/*.md are held to what the code does.

- README.md stays short (at most 15 000 characters) and undated; no page carries a date stamp.
- Every relative link points to a file that exists (and a `#anchor` into a Markdown page to one
  of its headings, as GitHub makes them).
- The scene-key reference in docs/design.md equals the parser's own schema, `scene.SCENE_KEYS`.
- Every TOML block that declares a `[[body]]` is a scene the parser accepts.
- Every `collide ...` command line in a shell code block runs and exits as documented, and
  every ```python block runs.

How commands are run (the convention for the pages' authors):

- A command is a line that starts with `collide ` inside a fenced block that is not toml, json
  or python. It runs with bash in a scratch folder per page (the venv's `collide` first on
  PATH), in page order: a later command may use what an earlier one wrote (a recording). The
  folder holds copies of `docs/scenes/` and `tests/data/`, so `docs/scenes/tilted-slide.toml`
  resolves; nothing is written into the work tree.
- It must exit 0, unless a trailing shell comment says otherwise (the shell ignores it):
  `# test: exit 2` (the exit code expected), `# test: args --set duration=0.05` (arguments
  appended, to shorten a long run), `# test: skip (why)`.
- An HTML comment on the line before a fenced block applies to the whole block:
  `<!-- test: skip (why) -->` skips its commands; `<!-- test: file NAME -->` before a TOML block
  writes it to the scratch folder as NAME before the page's commands run.
- `collide view ...` (without `--help`) starts a server: it runs with `--port 0` added when no
  port is given, passes once it prints its URL, and is then stopped.
- Commands that fail today because of work outside the docs are marked xfail below
  (`PENDING`), keyed on a part of the command line.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest

from collide.scene import SCENE_KEYS, parse_scene

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
PAGES = [README, *sorted((REPO / "docs").glob("*.md"))]
BIN = Path(sys.executable).parent
COMMAND_TIMEOUT = 600.0  # s: a first run may wait for the engine's compile
VIEW_TIMEOUT = 120.0  # s: until `collide view` prints its URL

# Documented behaviour that other branches are adding or fixing; remove an entry once merged.
PENDING = {
}


@dataclass
class Item:
    """One thing a page shows: a command line, a Python snippet, or a file to write first."""

    page: Path
    kind: str  # "command", "python" or "file"
    text: str
    line: int
    skip: str = ""
    expect: int = 0
    args: str = ""
    name: str = ""

    @property
    def id(self) -> str:
        shown = self.text if self.kind == "command" else f"python@{self.line}"
        return f"{self.page.relative_to(REPO)}:{shown}"


def _blocks(page: Path) -> list[tuple[str, str, list[tuple[int, str]]]]:
    """The fenced blocks of a page: (language, directive of the HTML comment before it, lines)."""
    lines = page.read_text().splitlines()
    blocks, index = [], 0
    while index < len(lines):
        match = re.match(r"^```(\w*)\s*$", lines[index])
        if not match:
            index += 1
            continue
        before = next((lines[j].strip() for j in range(index - 1, -1, -1) if lines[j].strip()), "")
        directive = re.fullmatch(r"<!--\s*test:\s*(.*?)\s*-->", before)
        end = next(j for j in range(index + 1, len(lines)) if lines[j].startswith("```"))
        body = [(j + 1, lines[j]) for j in range(index + 1, end)]
        blocks.append((match.group(1), directive.group(1) if directive else "", body))
        index = end + 1
    return blocks


def _command(page: Path, number: int, line: str, block_directive: str) -> Item:
    text, _, comment = line.partition("# test:")
    item = Item(page, "command", text.strip(), number)
    for directive in (block_directive, comment.strip()):
        if directive.startswith("skip"):
            item.skip = directive[4:].strip(" ()") or "skipped by the page"
        elif directive.startswith("exit"):
            item.expect = int(directive.split()[1])
        elif directive.startswith("args"):
            item.args = directive[4:].strip()
    return item


def page_items(page: Path) -> list[Item]:
    """Everything of one page that the tests run, in page order."""
    items = []
    for language, directive, body in _blocks(page):
        if language == "python":
            items.append(Item(page, "python", "\n".join(text for _, text in body), body[0][0] if body else 0))
        elif language == "toml":
            if directive.startswith("file"):
                items.append(Item(page, "file", "\n".join(t for _, t in body) + "\n", body[0][0],
                                  name=directive.split()[1]))
        elif language != "json":
            for number, text in body:
                stripped = text.strip().removeprefix("$ ")
                if stripped.startswith("collide "):
                    items.append(_command(page, number, stripped, directive))
    return items


ITEMS = [item for page in PAGES for item in page_items(page)]


def _runnable(page: Path) -> list[Item]:
    return [item for item in page_items(page) if item.kind != "file"]


@pytest.fixture(scope="module")
def workdirs(tmp_path_factory):
    """One scratch folder per page, holding the files the pages refer to."""
    made: dict[Path, Path] = {}

    def workdir(page: Path) -> Path:
        if page not in made:
            folder = tmp_path_factory.mktemp(page.stem)
            shutil.copytree(REPO / "docs" / "scenes", folder / "docs" / "scenes")
            shutil.copytree(REPO / "tests" / "data", folder / "tests" / "data",
                            ignore=shutil.ignore_patterns("*.py", "__pycache__"))
            for item in page_items(page):
                if item.kind == "file":
                    (folder / item.name).write_text(item.text)
            made[page] = folder
        return made[page]

    return workdir


def _env() -> dict[str, str]:
    return dict(os.environ, PATH=f"{BIN}{os.pathsep}{os.environ.get('PATH', '')}", COLUMNS="100")


def _run_view(command: str, cwd: Path) -> None:
    """Start `collide view`, wait for the URL it prints, stop it."""
    if "--port" not in command:
        command += " --port 0"
    process = subprocess.Popen(["bash", "-c", f"exec {command}"], cwd=cwd, env=_env(), text=True,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        deadline, seen = time.monotonic() + VIEW_TIMEOUT, []
        while time.monotonic() < deadline:
            line = process.stdout.readline()
            if not line and process.poll() is not None:
                break
            seen.append(line)
            if "http://" in line:
                return
        pytest.fail(f"`{command}` printed no URL (exit {process.poll()}):\n{''.join(seen)[-2000:]}")
    finally:
        os.killpg(process.pid, signal.SIGTERM)
        try:
            process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()


def _run_item(item: Item, cwd: Path) -> str | None:
    """Run one documented command or snippet in `cwd`; what went wrong, or None."""
    if item.kind == "python":
        done = subprocess.run([sys.executable, "-c", item.text], cwd=cwd, env=_env(), capture_output=True,
                              text=True, timeout=COMMAND_TIMEOUT)
        return None if done.returncode == 0 else f"the snippet at line {item.line} failed:\n{done.stderr[-2000:]}"
    command = f"{item.text} {item.args}".strip()
    if command.startswith("collide view") and "--help" not in command:
        try:
            _run_view(command, cwd)
        except pytest.fail.Exception as exc:
            return str(exc)
        return None
    done = subprocess.run(["bash", "-c", command], cwd=cwd, env=_env(), capture_output=True, text=True,
                          timeout=COMMAND_TIMEOUT)
    if done.returncode != item.expect:
        return (f"`{command}` exited {done.returncode}, documented {item.expect}:\n"
                f"{done.stdout[-1500:]}\n{done.stderr[-1500:]}")
    if item.expect == 0 and "Traceback" in done.stderr:
        return f"`{command}` printed a traceback:\n{done.stderr[-1500:]}"
    return None


# One test per page, its commands in page order in one folder: a later command reads what an
# earlier one wrote (a recording), and the test runner may spread tests over processes.
@pytest.mark.parametrize("page", PAGES, ids=lambda page: page.relative_to(REPO).as_posix())
def test_documented_commands_run(page: Path, workdirs) -> None:
    cwd = workdirs(page)
    failures = []
    for item in _runnable(page):
        if item.skip:
            continue
        problem = _run_item(item, cwd)
        pending = next((why for key, why in PENDING.items() if key in item.text), None)
        if problem and not pending:
            failures.append(f"{page.name}:{item.line}: {problem}")
    assert not failures, "\n\n".join(failures)


def test_the_pages_have_commands_to_run() -> None:
    """The parser of the pages finds what they show (so the test above is not vacuous)."""
    commands = [i.text for i in ITEMS if i.kind == "command"]
    assert "collide run demo-bonus" in commands
    assert any(i.kind == "python" for i in ITEMS)
    assert any(i.kind == "file" and i.name == "my-scene.toml" for i in ITEMS)


def test_the_convention_for_commands_is_read_as_documented(tmp_path) -> None:
    """The directives of the module docstring, on a page made for the purpose."""
    page = tmp_path / "page.md"
    page.write_text("\n".join([
        "```bash", "collide run demo-bonus", "collide run nothing.toml  # test: exit 2",
        "collide run pile  # test: args --set duration=0.05", "collide view  # test: skip (a server)",
        "echo collide run x", "```", "", "<!-- test: skip (needs a cluster) -->", "```bash",
        "$ collide batch demo-bonus --scheduler tcp://HOST:8786", "```", "<!-- test: file a.toml -->",
        "```toml", "dim = 1", "```", "```json", "collide run not-a-command", "```", "```python", "print(1)", "```"]))
    items = page_items(page)
    shown = [(i.kind, i.text, i.skip, i.expect, i.args, i.name) for i in items]
    assert shown == [
        ("command", "collide run demo-bonus", "", 0, "", ""),
        ("command", "collide run nothing.toml", "", 2, "", ""),
        ("command", "collide run pile", "", 0, "--set duration=0.05", ""),
        ("command", "collide view", "a server", 0, "", ""),
        ("command", "collide batch demo-bonus --scheduler tcp://HOST:8786", "needs a cluster", 0, "", ""),
        ("file", "dim = 1\n", "", 0, "", "a.toml"),
        ("python", "print(1)", "", 0, "", ""),
    ]


# ---------------------------------------------------------------------------------------------
# Size, dates, links


def test_readme_is_short_and_undated() -> None:
    text = README.read_text()
    assert len(text) <= 15_000, f"README.md has {len(text)} characters (at most 15 000)"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_no_date_stamps(page: Path) -> None:
    stamps = re.findall(r"\b\d{4}-\d{2}-\d{2}\b", page.read_text())
    assert not stamps, f"{page.name} carries date stamps: {stamps[:5]}"


def github_slugs(page: Path) -> set[str]:
    """The anchors GitHub gives a page's headings."""
    slugs: set[str] = set()
    text = re.sub(r"^```.*?^```", "", page.read_text(), flags=re.S | re.M)
    for heading in re.findall(r"^#{1,6}\s+(.*?)\s*$", text, flags=re.M):
        slug = re.sub(r"[^\w\- ]", "", heading.lower()).replace(" ", "-")
        candidate, n = slug, 1
        while candidate in slugs:
            candidate, n = f"{slug}-{n}", n + 1
        slugs.add(candidate)
    return slugs


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_relative_links_resolve(page: Path) -> None:
    text = re.sub(r"^```.*?^```", "", page.read_text(), flags=re.S | re.M)
    broken = []
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"^[a-z]+:", target):
            continue
        path, _, anchor = target.partition("#")
        file = (page.parent / path).resolve() if path else page
        if not file.exists():
            broken.append(f"{target} (no such file)")
        elif anchor and file.suffix == ".md" and anchor not in github_slugs(file):
            broken.append(f"{target} (no such heading)")
    assert not broken, f"{page.name}: broken links: {broken}"


def test_no_pointer_to_a_design_document_outside_the_repository() -> None:
    outside = "../" + "shared"
    old = "DESIGN" + " section"
    found = []
    for path in REPO.rglob("*"):
        if path.suffix not in (".py", ".md", ".toml") or {".venv", ".git"} & set(path.parts):
            continue
        text = path.read_text(errors="replace")
        if outside in text or old in text or "DESIGN" + ".md" in text:
            found.append(str(path.relative_to(REPO)))
    assert not found, f"cite docs/design.md instead: {found}"


# ---------------------------------------------------------------------------------------------
# The scene-key reference against the parser


TABLES = {"Top level": "scene", "`[contact]`": "contact", "`[[body]]`": "body", "`[[wall]]`": "wall",
          "`[[material]]`": "material", "`[[pair]]`": "pair", "`[domain]`": "domain", "`[[fill]]`": "fill",
          "`[bodies]`": "bodies"}


def documented_keys() -> dict[str, set[str]]:
    """The keys of each table of docs/design.md's scene-key reference (first column)."""
    text = (REPO / "docs" / "design.md").read_text()
    reference = text.split("### Scene-key reference", 1)[1].split("\n## ", 1)[0]
    keys: dict[str, set[str]] = {}
    for section in reference.split("\n#### ")[1:]:
        heading, _, body = section.partition("\n")
        if heading.strip() not in TABLES:
            continue
        rows = re.findall(r"^\|\s*`([^`]+)`\s*\|", body, flags=re.M)
        keys[TABLES[heading.strip()]] = set(rows)
    return keys


def test_scene_key_reference_matches_the_parser() -> None:
    documented = documented_keys()
    parser = {table: set(keys) for table, keys in SCENE_KEYS.items()}
    assert set(documented) == set(parser), "a table is missing from the reference or from SCENE_KEYS"
    for table in parser:
        assert documented[table] - parser[table] == set(), f"{table}: documented, but the parser refuses them"
        assert parser[table] - documented[table] == set(), f"{table}: accepted by the parser, but undocumented"


def test_the_parser_refuses_what_the_reference_does_not_list() -> None:
    """SCENE_KEYS is what the parser checks: in every table, a key outside it is refused by name."""
    from collide.scene import SceneError

    body = {"radius": 0.1, "mass": 1.0, "position": 0.0}
    base = {"dim": 1, "body": [body]}
    material = {"name": "m", "density": 1000.0}
    patches = {
        "scene": {"colour": 1},
        "contact": {"contact": {"colour": 1}},
        "body": {"body": [{**body, "colour": 1}]},
        "wall": {"wall": [{"point": 1.0, "normal": -1.0, "colour": 1}]},
        "material": {"material": [{**material, "colour": 1}]},
        "pair": {"material": [material], "pair": [{"materials": ["m", "m"], "colour": 1}]},
        "domain": {"domain": {"lower": -1.0, "upper": 1.0, "colour": 1}},
        "fill": {"fill": [{"lower": 1.0, "upper": 2.0, "count": 2, "radius": 0.1, "mass_density": 1.0,
                           "colour": 1}]},
        "bodies": {"bodies": {"file": str(REPO / "tests" / "data" / "bodies-1d.csv"), "colour": 1}},
    }
    assert set(patches) == set(SCENE_KEYS)
    parse_scene(base)
    for table, patch in patches.items():
        with pytest.raises(SceneError, match="unknown key 'colour'"):
            parse_scene({**base, **patch})
            pytest.fail(f"{table}: an unknown key was accepted")
        clean = {k: ([{f: v for f, v in t.items() if f != "colour"} for t in v] if isinstance(v, list) else
                     {f: w for f, w in v.items() if f != "colour"} if isinstance(v, dict) else v)
                 for k, v in patch.items() if k != "colour"}
        parse_scene({**base, **clean})  # the same table without the unknown key is accepted


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_toml_scenes_in_the_pages_parse(page: Path) -> None:
    for language, _, body in _blocks(page):
        text = "\n".join(t for _, t in body)
        if language == "toml" and "[[body]]" in text:
            parse_scene(tomllib.loads(text))
