"""Option values that need no conversion skip typer's conversion machinery.

typer (from 0.2x) converts every option's value, a default left alone included, through a
pydantic TypeAdapter built for that option: importing pydantic and building one adapter per
option cost `collide run` about a tenth of a second of CPU before anything ran. A value that is
already what the option holds (an option not given: None or its default of the right type; a
text argument) comes out of that conversion unchanged, so it is passed as it is; any other
value (a number or a path given as text, anything out of range) goes through typer as before,
with its own messages. Typers without that machinery are left alone.
"""

from __future__ import annotations

from typing import Any, get_args, get_origin


class _Unconverted:
    """typer's runtime conversion of one parameter, built only for a value that needs it."""

    def __init__(self, param: Any, build: Any) -> None:
        self.param, self.build, self.full = param, build, None

    def coerce(self, value: Any, param: Any, ctx: Any) -> Any:
        multiple = param.multiple or param.nargs == -1
        if value is None:  # as typer: nothing given
            return () if multiple else None
        descriptor = param.type_descriptor
        info = descriptor.parameter_info
        simple = descriptor.file_annotation is None and getattr(info, "parser", None) is None \
            and getattr(info, "click_type", None) is None
        if simple and not multiple and _as_is(descriptor.annotation, info, value):
            return value
        if simple and multiple and get_origin(descriptor.annotation) is list and isinstance(value, (list, tuple)):
            (item,) = get_args(descriptor.annotation) or (None,)
            if all(_as_is(item, info, v) for v in value):
                return list(value)
        if self.full is None:
            self.full = self.build(descriptor)
        return self.full.coerce(value, param=param, ctx=ctx)


def _as_is(annotation: Any, info: Any, value: Any) -> bool:
    """Whether typer's conversion gives `value` back unchanged: text for a text option, or a
    number of the option's own type within its bounds."""
    if annotation is str:
        return type(value) is str
    if annotation in (int, float) and type(value) is annotation and not getattr(info, "clamp", False):
        low, high = getattr(info, "min", None), getattr(info, "max", None)
        return (low is None or value >= low) and (high is None or value <= high)
    return False


def skip_needless_conversion() -> None:
    """Give typer's parameters the conversion above (once; only where typer has the machinery)."""
    try:
        from typer import core
        from typer._coercion import build_runtime_param
    except ImportError:
        return
    parameter = getattr(core, "_TyperParameter", None)
    if parameter is None or not hasattr(parameter, "get_runtime_param") or getattr(parameter, "_collide", False):
        return

    def get_runtime_param(self: Any) -> Any:
        if self._runtime_param is None:
            self._runtime_param = _Unconverted(self, build_runtime_param)
        return self._runtime_param

    parameter.get_runtime_param = get_runtime_param
    parameter._collide = True
