"""Plain-language messages for validation errors of scenario files.

pydantic reports where a value failed (a location with its own bookkeeping: union tags,
member names) and why, in its own words ("Input should be a valid tuple"). This module
turns each error into the key path the user wrote and a reason that says what was expected
and what was found ("expected a list of 2 numbers, got 3"), by walking the scenario's type
annotations along the error's location. Every field gets the same treatment; a field
added to `models.schema` needs nothing here.
"""

from __future__ import annotations

import difflib
import types
from collections.abc import Callable, Mapping
from typing import Annotated, Any, Literal, Union, get_args, get_origin

from pydantic import BaseModel, Tag

#: pydantic's names of union members, which may appear in an error location.
_MEMBER_LABELS = ("float", "int", "none", "tuple", "is-instance", "str", "bool", "dict", "list")

#: What each type error expected, when the field's annotation cannot say more.
_EXPECTED_BY_TYPE = {
    "float_type": "a number",
    "float_parsing": "a number",
    "int_type": "an integer",
    "int_parsing": "an integer",
    "int_from_float": "an integer",
    "bool_type": "true or false",
    "bool_parsing": "true or false",
    "string_type": "a string",
    "tuple_type": "a list",
    "list_type": "a list",
    "dict_type": "a table",
    "model_type": "a table",
    "model_attributes_type": "a table",
    "dataclass_type": "a table",
    "is_instance_of": "a table",
}
_RANGE = {
    "greater_than": "greater than",
    "greater_than_equal": "greater than or equal to",
    "less_than": "less than",
    "less_than_equal": "less than or equal to",
}
_RANGE_CTX = {"greater_than": "gt", "greater_than_equal": "ge", "less_than": "lt", "less_than_equal": "le"}


# ----------------------------------------------------------------------------- annotations


def _strip(tp: Any) -> tuple[Any, list]:
    """Remove Annotated layers; return the bare type and the metadata collected."""
    meta: list = []
    while get_origin(tp) is Annotated:
        args = get_args(tp)
        tp, meta = args[0], meta + list(args[1:])
    return tp, meta


def _is_union(tp: Any) -> bool:
    return get_origin(tp) in (Union, types.UnionType)


def _is_model(tp: Any) -> bool:
    return isinstance(tp, type) and issubclass(tp, BaseModel)


def _members(tp: Any) -> list:
    return [m for m in get_args(tp) if m is not type(None)]


def _tag(member: Any) -> str | None:
    """The discriminator tag of a union member: a `Tag`, or a model's literal `type`."""
    bare, meta = _strip(member)
    for m in meta:
        if isinstance(m, Tag):
            return m.tag
    if _is_model(bare) and "type" in bare.model_fields:
        values = get_args(_strip(bare.model_fields["type"].annotation)[0])
        if len(values) == 1:
            return values[0]
    return None


def walk(root: type[BaseModel], loc: tuple) -> tuple[tuple, Any]:
    """Follow an error location through the annotations of `root`.

    Returns the location as the user wrote it (union tags and member names dropped) and the
    annotation of the field the error is about (None when the walk lost its way)."""
    clean: list = []
    tp: Any = root
    i = 0
    while i < len(loc):
        part = loc[i]
        if tp is None:
            if not (isinstance(part, str) and (any(c in part for c in "[]()") or part in _MEMBER_LABELS)):
                clean.append(part)
            i += 1
            continue
        tp, _ = _strip(tp)
        if _is_union(tp):
            members = _members(tp)
            if len(members) == 1:
                tp = members[0]
                continue
            tagged = {_tag(m): m for m in members}
            if isinstance(part, str) and part in tagged:
                tp = tagged[part]
                i += 1  # a union tag: not a key in the file
                continue
            tp = None
            continue
        if _is_model(tp):
            field = next((f for name, f in tp.model_fields.items() if (f.alias or name) == part), None)
            clean.append(part)
            tp = field.annotation if field is not None else None
        elif get_origin(tp) is tuple and isinstance(part, int):
            args = get_args(tp)
            clean.append(part)
            tp = args[0] if len(args) == 2 and args[1] is Ellipsis else (args[part] if part < len(args) else None)
        elif get_origin(tp) is dict:
            key_type, value_type = get_args(tp)
            if part == "[key]":
                tp = key_type
            else:
                clean.append(part)
                tp = value_type
        else:
            tp = None
            continue
        i += 1
    return tuple(clean), tp


def describe(tp: Any) -> tuple[str, str, bool] | None:
    """(singular, plural, fixed length) of what an annotation accepts, e.g.
    ("a list of 2 numbers", "lists of 2 numbers", True); None if it cannot say."""
    if tp is None:
        return None
    tp, _ = _strip(tp)
    if _is_union(tp):
        members = _members(tp)
        if len(members) == 1:
            return describe(members[0])
        tags = [_tag(m) for m in members]
        if all(t is not None for t in tags):
            kind = "shape" if all(_is_model(_strip(m)[0]) and "type" in _strip(m)[0].model_fields for m in members) else "predicate"
            return f"a {kind} table", f"{kind} tables", False
        return None
    if tp is float:
        return "a number", "numbers", False
    if tp is bool:
        return "true or false", "booleans (true or false)", False
    if tp is int:
        return "an integer", "integers", False
    if tp is str:
        return "a string", "strings", False
    if get_origin(tp) is Literal:
        values = [repr(v) for v in get_args(tp)]
        text = values[0] if len(values) == 1 else f"{', '.join(values[:-1])} or {values[-1]}"
        return text, text, False
    if get_origin(tp) is tuple:
        args = get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:
            item = describe(args[0])
            return (f"a list of {item[1]}", f"lists of {item[1]}", False) if item else ("a list", "lists", False)
        items = [describe(a) for a in args]
        if items and all(it is not None and it[:2] == items[0][:2] for it in items):
            return f"a list of {len(args)} {items[0][1]}", f"lists of {len(args)} {items[0][1]}", True
        return f"a list of {len(args)} entries", f"lists of {len(args)} entries", True
    if get_origin(tp) is dict or _is_model(tp):
        return "a table", "tables", False
    return None


# ----------------------------------------------------------------------------- messages


def got(value: Any) -> str:
    """How an offending input is quoted in a message."""
    if isinstance(value, bool):
        return f"the boolean {str(value).lower()}"
    if isinstance(value, (list, tuple)):
        return f"a list of {len(value)} {'entry' if len(value) == 1 else 'entries'}"
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, float):
        return f"{value:g}"
    return repr(value)


def _entries(n: Any) -> str:
    return f"{n} {'entry' if n == 1 else 'entries'}"


def keys_at(root: type[BaseModel], loc: tuple) -> tuple[str, ...]:
    """The keys the table at `loc` (an error location of `root`) takes, as a file spells them;
    empty where that is not a table of fixed keys (a table of names, or a walk that lost its way)."""
    _, tp = walk(root, loc)
    if tp is None:
        return ()
    tp, _ = _strip(tp)
    if _is_union(tp):
        models = [m for m in _members(tp) if _is_model(_strip(m)[0])]
        tp = _strip(models[0])[0] if len(models) == 1 else None
    return tuple(f.alias or name for name, f in tp.model_fields.items()) if _is_model(tp) else ()


def unknown_key(key: str, known: tuple[str, ...]) -> str:
    """The reason for an unknown key, with the closest key the table takes, else its keys."""
    close = difflib.get_close_matches(key, known, n=1, cutoff=0.6)
    if close:
        hint = f"did you mean {close[0]!r}?"
    elif known:
        hint = f"this table takes: {', '.join(known)}"
    else:
        hint = "check the spelling"
    return f"unknown key ({hint}{'' if hint.endswith('?') else '.'} See docs/scenario-format.md)"


def reason(err: Mapping[str, Any], annotation: Any, shown: Callable[[Any], str] = got, known: tuple[str, ...] = ()) -> tuple[str, str]:
    """(key suffix, reason) of one pydantic error; the suffix is appended to the key path
    (a union's discriminator key, e.g. ``.type``, when that is what was wrong). known: the keys
    the table of an unknown key takes (`keys_at`)."""
    kind = err["type"]
    ctx = err.get("ctx") or {}
    value = err.get("input")
    message = err["msg"]
    what = describe(annotation)
    if kind == "missing":
        return "", "required key is missing"
    if kind == "extra_forbidden":
        return "", unknown_key(str(err["loc"][-1]), known)
    if kind in ("value_error", "assertion_error"):
        for prefix in ("Value error, ", "Assertion failed, "):
            if message.startswith(prefix):
                message = message[len(prefix) :]
        return "", message
    if kind in _EXPECTED_BY_TYPE:
        expected = what[0] if what and kind not in ("int_from_float",) else _EXPECTED_BY_TYPE[kind]
        return "", f"expected {expected}, got {got(value)}"
    if kind in ("too_short", "too_long"):
        actual = ctx.get("actual_length", len(value) if isinstance(value, (list, tuple, dict)) else "?")
        if what is not None and what[2]:
            return "", f"expected {what[0]}, got {_entries(actual)}"
        if kind == "too_short":
            return "", f"needs at least {_entries(ctx.get('min_length'))}, got {actual}"
        return "", f"takes at most {_entries(ctx.get('max_length'))}, got {actual}"
    if kind == "literal_error":
        return "", f"expected {ctx.get('expected', what[0] if what else 'one of the allowed values')}, got {got(value)}"
    if kind in _RANGE:
        return "", f"must be {_RANGE[kind]} {ctx.get(_RANGE_CTX[kind])}, got {shown(value)}"
    if kind == "string_pattern_mismatch":
        if ctx.get("pattern") == r"^[A-Za-z_][A-Za-z0-9_]*$":
            return "", f"expected a name of letters, digits and underscores, not starting with a digit, got {got(value)}"
        return "", f"does not match the pattern {ctx.get('pattern')}, got {got(value)}"
    if kind == "union_tag_invalid":
        key = str(ctx.get("discriminator", "")).strip("'")
        suffix = f".{key}" if key.isidentifier() else ""
        return suffix, f"unknown {key or 'kind'} {ctx.get('tag')!r}; expected one of {ctx.get('expected_tags')}"
    if kind == "union_tag_not_found":
        key = str(ctx.get("discriminator", "")).strip("'")
        return (f".{key}", "required key is missing") if key.isidentifier() else ("", message)
    if message.startswith("Input should be "):
        message = "expected " + message[len("Input should be ") :]
    if value is not None and not isinstance(value, (dict, list)):
        message += f", got {got(value)}"
    return "", message
