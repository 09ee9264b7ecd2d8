"""Scene text to a table: `tomllib`, with a quick path for the `[[body]]` tables of large scenes.

`tomllib` takes about 50 us per body table (5 s for 1e5 bodies). The quick path reads a
`[[body]]` table whose lines are each `key = value` with a plain value (a decimal number, a
string without escapes, true/false, or a one-line array of numbers), and hands everything else
to `tomllib`. Whenever anything is not that plain (a multi-line string anywhere, a body line
that does not match, a key given twice, a `body` key outside the tables), the whole text goes to
`tomllib`, so the table is always what `tomllib` makes of the text and every error is its own.
"""

from __future__ import annotations

import re
import tomllib
from typing import Any

QUICK_MIN_BODIES = 64  # fewer [[body]] tables: tomllib alone
SEEN_MAX = 4096

_NUMBER = r"[+-]?(?:0|[1-9][0-9]*)(?:\.[0-9]+)?(?:[eE][+-]?[0-9]+)?"
_VALUE = (rf"(?P<num>{_NUMBER})|\"(?P<basic>[^\"\\\x00-\x1f\x7f]*)\"|'(?P<literal>[^'\x00-\x1f\x7f]*)'"
          rf"|(?P<bool>true|false)"
          rf"|(?P<open>\[)[ \t]*(?:(?P<array>{_NUMBER}(?:[ \t]*,[ \t]*{_NUMBER})*)[ \t]*,?[ \t]*)?\]")
_LINE = re.compile(rf"[ \t]*(?P<key>[A-Za-z0-9_-]+)[ \t]*=[ \t]*(?:{_VALUE})[ \t]*(?:#[^\x00-\x08\x0a-\x1f\x7f]*)?")
_BLANK = re.compile(r"[ \t]*(?:#[^\x00-\x08\x0a-\x1f\x7f]*)?")
_SPLIT = re.compile(r"[ \t]*,[ \t]*")


class FlatTables(list):
    """`[[body]]` tables read by the quick path: each value a number, string, boolean or flat
    array of numbers, so no deeper than the scene's depth limit (collide.scene skips them)."""


def _number(text: str) -> int | float:
    return float(text) if "." in text or "e" in text or "E" in text else int(text)


def _value(match: re.Match) -> Any:
    kind = match.lastgroup
    if kind == "num":
        return _number(match["num"])
    if kind == "array":
        return [_number(x) for x in _SPLIT.split(match["array"])]
    if kind == "open":
        return []
    if kind == "bool":
        return match["bool"] == "true"
    return match[kind]


def _body(lines: list[str], seen: dict[str, tuple[str, Any]]) -> dict | None:
    """One body table; `seen` keeps lines of a scalar value already read (many bodies share a
    radius or a mass line), whose values need no copy."""
    table: dict[str, Any] = {}
    for line in lines:
        known = seen.get(line)
        if known is not None:
            key, value = known
        else:
            found = _LINE.fullmatch(line)
            if found is None:
                if _BLANK.fullmatch(line):
                    continue
                return None
            key, value = found["key"], _value(found)
            if type(value) is not list and len(seen) < SEEN_MAX:
                seen[line] = (key, value)
        if key in table:
            return None
        table[key] = value
    return table


def _quick(text: str) -> dict | None:
    """The table, or None when the text is not plain enough for the quick path."""
    if text.count("[[body]]") < QUICK_MIN_BODIES or '"""' in text or "'''" in text or "\r" in text:
        return None
    rest: list[str] = []
    bodies: list[dict] = []
    section: list[str] | None = None
    for line in text.split("\n"):
        stripped = line.strip()
        if stripped == "[[body]]":
            if section is not None:
                bodies.append(section)  # type: ignore[arg-type]
            section = []
            continue
        if section is not None and stripped.startswith("["):
            bodies.append(section)  # type: ignore[arg-type]
            section = None
        (rest if section is None else section).append(line)
    if section is not None:
        bodies.append(section)  # type: ignore[arg-type]
    seen: dict[str, tuple[str, Any]] = {}
    tables = [_body(lines, seen) for lines in bodies]  # type: ignore[arg-type]
    if any(t is None for t in tables):
        return None
    try:
        out = tomllib.loads("\n".join(rest))
    except tomllib.TOMLDecodeError:
        return None
    if "body" in out:
        return None
    out["body"] = FlatTables(tables)
    return out


def loads_scene(text: str) -> dict:
    """`tomllib.loads(text)`, quicker for many plain `[[body]]` tables (same table, same errors)."""
    quick = _quick(text)
    return quick if quick is not None else tomllib.loads(text)
