"""A scene's validation errors in words: each of pydantic's errors becomes one
``FILE:LINE:COLUMN: key.path: message`` diagnostic at the line of the value it is
about, with a did-you-mean for a misspelt key, type or method.
"""

from __future__ import annotations

import difflib
import re
import types
from collections.abc import Sequence
from typing import Annotated, Any, Union, get_args, get_origin

from pydantic import BaseModel, ValidationError

from animsim import methods
from animsim.errors import Diagnostic, UsageError
from animsim.scene.models import HEX_COLOR_PATTERN, OPAQUE_COLOR_PATTERN, Scene
from animsim.scene.yaml_reader import Marks, Path_, dotted


def _data_path(loc: tuple[Any, ...], data: Any) -> tuple[Path_, tuple[Any, ...]]:
    """Split a pydantic loc into the path through the data, dropping union tags.

    Returns (path that exists in the data, the loc segments that were skipped
    or left over at the end).
    """
    path: list[Any] = []
    cur = data
    rest: list[Any] = []
    for seg in loc:
        if (isinstance(cur, dict) and seg in cur) or (
            isinstance(cur, list) and isinstance(seg, int) and 0 <= seg < len(cur)
        ):
            path.append(seg)
            cur = cur[seg]
        else:
            rest.append(seg)
    return tuple(path), tuple(rest)


def _unwrap(tp: Any) -> list[Any]:
    """The concrete alternatives behind Annotated/Union/Optional."""
    origin = get_origin(tp)
    if origin is Annotated:
        return _unwrap(get_args(tp)[0])
    if origin is Union or origin is types.UnionType:
        out: list[Any] = []
        for a in get_args(tp):
            out.extend(_unwrap(a))
        return out
    return [tp]


def _models_at(loc: tuple[Any, ...]) -> list[type[BaseModel]]:
    """The model classes that could sit at ``loc`` (pydantic loc, tags included)."""
    current: list[Any] = [Scene]
    for seg in loc:
        nxt: list[Any] = []
        for tp in current:
            for alt in _unwrap(tp):
                if isinstance(alt, type) and issubclass(alt, BaseModel):
                    if isinstance(seg, str) and seg in alt.model_fields:
                        nxt.append(alt.model_fields[seg].annotation)
                    elif isinstance(seg, str) and seg in (_tag_of(alt), alt.__name__):
                        nxt.append(alt)
                elif get_origin(alt) is list and isinstance(seg, int):
                    nxt.append(get_args(alt)[0])
        current = nxt
    return [a for tp in current for a in _unwrap(tp) if isinstance(a, type) and issubclass(a, BaseModel)]


def _tag_of(model: type[BaseModel]) -> str | None:
    f = model.model_fields.get("type")
    if f is None:
        return None
    args = get_args(f.annotation)
    return args[0] if args else None


# Names users reach for that the scene language spells differently: a
# did-you-mean that spelling distance alone would never find.
TYPE_ALIASES = {
    "hair": "strand",
    "rope": "strand",
    "chain": "strand",
    "string": "strand",
    "jello": "soft_box",
    "jelly": "soft_box",
    "softbox": "soft_box",
    "soft_body": "soft_box",
    "softbody": "soft_box",
    "cube": "soft_box",
    "sheet": "cloth",
    "fabric": "cloth",
    "flag": "cloth",
    "ball": "sphere",
    "circle": "disc",
    "disk": "disc",
    "damping": "drag",
    "air_resistance": "drag",
    "gravitation": "attractor",
}


def _normal(word: str) -> str:
    return word.strip().lower().replace("-", "_").replace(" ", "_")


def did_you_mean(word: Any, choices: Sequence[str]) -> str:
    """``; did you mean 'x'?``: by case and spelling (RK4, Soft-Box), by alias (hair), then by distance."""
    if not isinstance(word, str):
        return ""
    choices = list(choices)
    by_case = {_normal(c): c for c in choices}
    norm = _normal(word)
    if norm in by_case and by_case[norm] != word:
        return f"; did you mean '{by_case[norm]}'?"
    alias = TYPE_ALIASES.get(norm) or methods.aliases().get(norm)
    if alias in choices:
        return f"; did you mean '{alias}'?"
    close = difflib.get_close_matches(norm, list(by_case), n=1, cutoff=0.6)
    return f"; did you mean '{by_case[close[0]]}'?" if close else ""


def method_from_option(name: str, option: str) -> str:
    """``name`` if it is a registered method, else a UsageError for ``option`` with a did-you-mean."""
    known = methods.names()
    if name in known:
        return name
    hint = did_you_mean(name, known)
    raise UsageError(f"{option}: unknown method {name!r}{hint} (valid: {', '.join(known)})")


_KIND = {
    "float_type": "a number",
    "float_parsing": "a number",
    "int_type": "an integer",
    "int_parsing": "an integer",
    "string_type": "a string",
    "bool_type": "true or false",
    "list_type": "a list",
    "dict_type": "a mapping",
    "model_type": "a mapping",
    "model_attributes_type": "a mapping",
}


# pydantic bound errors: (how to say it, the ctx key holding the bound)
_BOUND = {
    "greater_than": ("greater than", "gt"),
    "greater_than_equal": ("greater than or equal to", "ge"),
    "less_than": ("less than", "lt"),
    "less_than_equal": ("less than or equal to", "le"),
}
_VECTOR_KEYS = {
    "position",
    "velocity",
    "g",
    "point",
    "normal",
    "center",
    "origin",
    "start",
    "end",
    "min",
    "max",
    "mean",
}


def _short(value: Any) -> str:
    r = repr(value)
    return r if len(r) <= 40 else r[:37] + "..."


def diagnostics(exc: ValidationError, data: dict[str, Any], marks: Marks, file: str) -> list[Diagnostic]:
    groups: dict[Path_, list[dict[str, Any]]] = {}
    for err in exc.errors(include_url=False):
        loc = err["loc"]
        if err["type"] == "missing":
            path, _ = _data_path(loc[:-1], data)
            key = (*path, loc[-1])
        else:
            key, _ = _data_path(loc, data)
        groups.setdefault(key, []).append(err)
    # A union reports each branch: when the value matched one branch's shape
    # (a mapping for IntegratorSpec) and failed deeper, the other branches'
    # "is not one of the names" errors are noise about the same value.
    for path in list(groups):
        deeper = any(len(other) > len(path) and other[: len(path)] == path for other in groups)
        if deeper and all(e["type"] in _KIND or e["type"] == "literal_error" for e in groups[path]):
            del groups[path]
    # One typo, one message: a missing key that an unknown sibling key's
    # did-you-mean already names is not reported again.
    suggested = set()
    for path, errs in groups.items():
        if any(e["type"] == "extra_forbidden" for e in errs):
            allowed = sorted({f for m in _models_at(errs[0]["loc"][:-1]) for f in m.model_fields})
            close = difflib.get_close_matches(str(path[-1]), allowed, n=1, cutoff=0.6)
            if close:
                suggested.add((*path[:-1], close[0]))
    out: list[Diagnostic] = []
    for path, errs in groups.items():
        if errs[0]["type"] == "missing" and path in suggested:
            continue
        msg, at_key = _message(path, errs, marks)
        if errs[0]["type"] == "missing":
            line, col = marks.at(path[:-1])
        else:
            line, col = marks.at(path, prefer_key=at_key)
        out.append(Diagnostic(file, line, col, dotted(path), msg))
    return out


def _mapping_fields(err: dict[str, Any]) -> list[tuple[str, bool]]:
    """(key, required) of the one model expected where ``err`` found no mapping; [] if unclear."""
    models = _models_at(err["loc"])
    if len(models) != 1:
        return []
    return [(name, f.is_required()) for name, f in models[0].model_fields.items()]


def _mapping_hint(err: dict[str, Any]) -> str:
    """``lifetime: 2`` -> name the keys the mapping takes, and the likely fix."""
    fields = _mapping_fields(err)
    keys = ", ".join(f"{k} (required)" if req else k for k, req in fields)
    msg = f"expected a mapping with keys {keys}; got {_short(err['input'])}"
    required = [k for k, req in fields if req]
    value = err["input"]
    if len(required) == 1 and isinstance(value, int | float) and not isinstance(value, bool):
        msg += f" (write {{{required[0]}: {value}}})"
    return msg


# Patterns of the scene language, said in words (pydantic would show the regex).
_PATTERN_WORDS = {
    HEX_COLOR_PATTERN: "a colour written #rrggbb or #rrggbbaa in hexadecimal (e.g. #ff8000)",
    OPAQUE_COLOR_PATTERN: "a colour written #rrggbb in hexadecimal (e.g. #3070d0); a body is opaque",
}


def _pattern_message(err: dict[str, Any]) -> str:
    pattern = err.get("ctx", {}).get("pattern")
    words = _PATTERN_WORDS.get(pattern, f"text matching {pattern}")
    return f"expected {words}, got {_short(err['input'])}"


def _message(path: Path_, errs: list[dict[str, Any]], marks: Marks) -> tuple[str, bool]:
    """One message for all errors at one place (a union reports one per branch)."""
    types = [e["type"] for e in errs]
    first = errs[0]
    hint = marks.hints.get(path)
    if "extra_forbidden" in types:
        e = errs[types.index("extra_forbidden")]
        allowed = sorted({f for m in _models_at(e["loc"][:-1]) for f in m.model_fields})
        return f"unknown key{did_you_mean(path[-1], allowed)} (allowed: {', '.join(allowed)})", True
    if "missing" in types:
        return "required key is missing", False
    if "union_tag_invalid" in types:
        e = errs[types.index("union_tag_invalid")]
        tags = [t.strip(" '") for t in e["ctx"]["expected_tags"].split(",")]
        return (
            f"unknown type {e['ctx']['tag']!r}{did_you_mean(e['ctx']['tag'], tags)} (valid: {', '.join(tags)})",
            False,
        )
    if "union_tag_not_found" in types:
        return "needs a 'type' key", False
    if "literal_error" in types:
        e = errs[types.index("literal_error")]
        choices = re.findall(r"'([^']*)'", e["ctx"]["expected"])
        return (
            f"{_short(e['input'])} is not one of: {', '.join(choices)}{did_you_mean(e['input'], choices)}",
            False,
        )
    if len(errs) > 1 and all(t in _KIND for t in types):
        kinds = " or ".join(dict.fromkeys(_KIND[t] for t in types))
        msg = f"expected {kinds}, got {_short(first['input'])}"
    elif first["type"] in ("model_type", "model_attributes_type", "dict_type") and _mapping_fields(first):
        msg = _mapping_hint(first)
    elif first["type"] == "string_pattern_mismatch":
        msg = _pattern_message(first)
    elif first["type"] in _KIND:
        msg = f"expected {_KIND[first['type']]}, got {_short(first['input'])}"
        value = first["input"]
        if (
            first["type"] in ("float_type", "int_type")
            and isinstance(value, int)
            and not isinstance(value, bool)
        ):
            msg = f"the number {_short(value)} is too large"
        elif first["type"] == "int_type" and isinstance(value, float) and value.is_integer():
            msg += f" (write it without a decimal point or exponent: {int(value)})"
    elif first["type"] in _BOUND and "ctx" in first:
        op, key = _BOUND[first["type"]]
        bound = first["ctx"][key]
        shown = f"{bound:g}" if isinstance(bound, float) else repr(bound)
        msg = f"must be {op} {shown}, got {_short(first['input'])}"
    elif first["type"] in ("too_short", "too_long") and "ctx" in first:
        ctx = first["ctx"]
        lo, hi = ctx.get("min_length"), ctx.get("max_length")
        want = f"at least {lo}" if first["type"] == "too_short" else f"at most {hi}"
        msg = f"expected {want} items, got {ctx.get('actual_length')}"
        if path and path[-1] in _VECTOR_KEYS:
            msg += " (a vector is [x, y, z], or [x, y] meaning z = 0)"
    elif first["type"] == "finite_number":
        msg = "must be a finite number (no .nan, .inf, or overflowing values)"
    elif first["type"] == "value_error":
        msg = str(first["ctx"]["error"]) if "ctx" in first else first["msg"]
    else:
        msg = first["msg"]
        msg = msg[0].lower() + msg[1:]
    if hint:
        msg = f"{msg} ({hint})"
    return msg, False
