"""Strict schemas of the user's files: value types, sections that refuse unknown keys, and one
message listing every problem with its key.

A file type declares its schema as :class:`Section` models built from the types below, and
:func:`validate_section` checks a whole file (every section and sub-section) at load:

- :data:`Number` (a finite int or float; never ``true``, never text such as ``"0.3"`` or YAML
  1.1's ``1.0e6``), :data:`WholeNumber` (``2`` or ``2.0``; not ``2.5``, ``true`` or ``"two"``),
  :data:`Flag` (``true``/``false`` only), :data:`Text`, :data:`Pair` (``[low, high]``),
- :class:`Section`: a mapping whose keys are its fields; any other key is refused
  (``extra="forbid"``), naming the valid ones.

Messages follow the project's style: ``<file>: <key> must be <what>, got <value>`` (a key path
such as ``responses[0].replicates``); several problems are listed one per line.
"""
from __future__ import annotations

import dataclasses
import functools
import math
import numbers
import types
import typing
from typing import Annotated, Any, Mapping, Optional, Sequence, TypeVar, get_args

from pydantic import BaseModel, BeforeValidator, ConfigDict, StrictBool, StrictStr, Tag, ValidationError, create_model

from .errors import ConfigError

__all__ = ["Section", "Number", "WholeNumber", "Flag", "Text", "Pair", "yaml_number_hint", "validate_section",
           "problem_lines", "raise_problems", "dataclass_section"]


def yaml_number_hint(value: Any) -> str:
    """A hint for a number that YAML read as text (``1.0e6``: YAML 1.1 needs ``1.0e+6``)."""
    if isinstance(value, str):
        try:
            float(value)
        except ValueError:
            return ""
        if "e" in value.lower():
            return (" (text, not a number: YAML reads an exponent without a dot and a sign, such as 1.0e6 or 1e-5, "
                    "as text; write 1.0e+6 or 1.0e-5)")
        return " (text, not a number: write it without quotes)"
    return ""


def _number(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"must be a number{yaml_number_hint(value)}")
    x = float(value)
    if not math.isfinite(x):
        raise ValueError("must be a finite number")
    return x


def _whole_number(value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"must be a whole number{yaml_number_hint(value)}")
    if isinstance(value, numbers.Integral):
        return int(value)
    if not (math.isfinite(float(value)) and float(value).is_integer()):
        raise ValueError("must be a whole number")
    return int(value)


def _pair(value: Any) -> Any:
    if isinstance(value, (str, bytes, Mapping)) or not hasattr(value, "__len__") or len(value) != 2:
        raise ValueError("must be [low, high] (two numbers)")
    return tuple(value)


#: a finite number (int or float; numpy scalars too); not a boolean, not text
Number = Annotated[float, BeforeValidator(_number)]
#: a whole number (``2`` or ``2.0``); not ``2.5``, a boolean or text
WholeNumber = Annotated[int, BeforeValidator(_whole_number)]
#: ``true`` or ``false`` (not ``"yes"``, not 1)
Flag = StrictBool
#: text (not a number)
Text = StrictStr
#: two numbers ``[low, high]`` (order checked by the section that uses it)
Pair = Annotated[tuple[Number, Number], BeforeValidator(_pair)]


class Section(BaseModel):
    """A mapping of a user's file: its fields and nothing else (an unknown key is refused)."""

    model_config = ConfigDict(extra="forbid")


M = TypeVar("M", bound=BaseModel)

_SCALARS = {float: Number, int: WholeNumber, bool: Flag, str: Text}


def _strict_type(annotation: Any) -> Any:
    """The strict schema type of a dataclass field's annotation: ``float`` -> :data:`Number`,
    ``int`` -> :data:`WholeNumber`, ``bool`` -> :data:`Flag`, ``str`` -> :data:`Text`,
    ``tuple[float, float]`` -> :data:`Pair`, ``dict[str, float]``, each optional where the field
    is ``X | None``; Any for what the dataclass checks itself (objects, mappings of objects)."""
    if annotation in _SCALARS:
        return _SCALARS[annotation]
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin in (typing.Union, types.UnionType) and type(None) in args and len(args) == 2:
        inner = _strict_type(next(a for a in args if a is not type(None)))
        return Any if inner is Any else Optional[inner]
    if origin is tuple and args == (float, float):
        return Pair
    if origin is dict and args == (str, float):
        return dict[Text, Number]
    return Any


@functools.cache
def dataclass_section(cls: type, exclude: tuple[str, ...] = ()) -> type[Section]:
    """A :class:`Section` with one field per field of the dataclass ``cls`` (less ``exclude``),
    typed by :func:`_strict_type`; every field optional (only the keys given are checked, the
    dataclass keeps its defaults), any other key refused."""
    hints = typing.get_type_hints(cls)
    fields = {f.name: (_strict_type(hints[f.name]), None) for f in dataclasses.fields(cls) if f.name not in exclude}
    return create_model(f"{cls.__name__}Section", __base__=Section, **fields)

_COMPARISONS = {"greater_than": ("gt", ">"), "greater_than_equal": ("ge", ">="), "less_than": ("lt", "<"),
                "less_than_equal": ("le", "<=")}
_TYPES = {"int_type": "a whole number", "int_parsing": "a whole number", "int_from_float": "a whole number",
          "float_type": "a number", "float_parsing": "a number", "bool_type": "true or false",
          "bool_parsing": "true or false", "string_type": "text", "list_type": "a list", "tuple_type": "a list",
          "dict_type": "a mapping", "model_type": "a mapping", "model_attributes_type": "a mapping",
          "finite_number": "a finite number"}


def _path(loc: Sequence[Any]) -> str:
    """``responses[0].target`` from pydantic's location (union tags in parentheses left out)."""
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif isinstance(part, str) and (part.startswith("(") or part == "[key]"):  # a union tag, a mapping's key
            continue
        else:
            out += f".{part}" if out else str(part)
    return out


def _sub_models(annotation: Any, tag: str | None = None) -> list[tuple[str | None, type[BaseModel]]]:
    """The Sections inside ``annotation`` (``X``, ``X | None``, ``list[X]``, ``dict[str, X]``, a
    tagged union) with the union tag each sits under."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [(tag, annotation)]
    found = []
    for meta in getattr(annotation, "__metadata__", ()):
        if isinstance(meta, Tag):
            tag = meta.tag
    for arg in get_args(annotation):
        found += _sub_models(arg, tag)
    return found


def _valid_keys(model: type[BaseModel] | None, loc: Sequence[Any]) -> list[str] | None:
    """The field names of the section that holds the key at ``loc`` (None where unknown)."""
    candidates: list[tuple[str | None, type[BaseModel]]] = [(None, model)] if model is not None else []
    for part in loc[:-1]:
        if isinstance(part, str) and part.startswith("("):  # a union tag: the member it names
            candidates = [c for c in candidates if c[0] == part]
        elif isinstance(part, str):
            models = [m for _, m in candidates if part in m.model_fields]
            candidates = _sub_models(models[0].model_fields[part].annotation) if models else []
    models = [m for _, m in candidates]
    return sorted(models[0].model_fields) if len(models) == 1 else None


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def problem_lines(exc: ValidationError, model: type[BaseModel] | None = None, prefix: str = "") -> list[str]:
    """One line per problem of a pydantic ValidationError, in the project's words:
    ``<key> must be <what>, got <value>`` (``prefix``: a key path the locations are under)."""
    lines = []
    for err in exc.errors():
        path = _path([*([prefix] if prefix else []), *err["loc"]]) or "(top level)"
        kind, ctx, given = err["type"], err.get("ctx") or {}, err.get("input")
        if kind == "extra_forbidden":
            valid = _valid_keys(model, err["loc"])
            lines.append(f"{path}: unknown key" + (f"; valid: {', '.join(valid)}" if valid else ""))
            continue
        if kind == "missing":
            lines.append(f"{path} is missing (required)")
            continue
        if kind in _COMPARISONS:
            key, sign = _COMPARISONS[kind]
            bound = ctx.get(key)
            what = f"must be {sign} {bound:g}" if isinstance(bound, (int, float)) else f"must be {sign} {bound}"
        elif kind in _TYPES:
            what = f"must be {_TYPES[kind]}" + (yaml_number_hint(given) if kind.startswith(("float", "int")) else "")
        elif kind == "literal_error":
            what = f"must be one of {ctx.get('expected')}"
        elif kind == "string_too_short":
            what = "must not be empty"
        elif kind in ("too_short", "too_long"):
            n = ctx.get("min_length") if kind == "too_short" else ctx.get("max_length")
            what = f"must have {'at least' if kind == 'too_short' else 'at most'} {n} item(s)"
        else:
            what = str(err["msg"]).removeprefix("Value error, ").removeprefix("Assertion failed, ")
        sep = " " if what.startswith(("must ", "is ")) else ": "
        got = "" if isinstance(given, Mapping) and kind not in _TYPES else f", got {_shown(given)}"
        lines.append(f"{path}{sep}{what}{got}")
    return lines


def raise_problems(source: str, problems: Sequence[str]) -> None:
    """Raise one ConfigError listing ``problems`` of the file ``source`` (nothing if none)."""
    if len(problems) == 1:
        raise ConfigError(f"{source}: {problems[0]}")
    if problems:
        raise ConfigError(f"{source}: {len(problems)} problems:\n" + "\n".join(f"  - {p}" for p in problems))


def validate_section(model: type[M], raw: Any, source: str, context: Mapping[str, Any] | None = None,
                     prefix: str = "") -> M:
    """``raw`` (a file's parsed mapping, or a part of it under the key path ``prefix``) checked
    against ``model``; every problem listed in one ConfigError naming ``source`` and each key."""
    if not isinstance(raw, Mapping):
        where = f"{prefix} must be" if prefix else "the top level must be"
        raise ConfigError(f"{source}: {where} a mapping of keys, got {_shown(raw)}")
    try:
        return model.model_validate(dict(raw), context=dict(context or {}))
    except ValidationError as exc:
        raise_problems(source, problem_lines(exc, model, prefix))
        raise AssertionError("unreachable") from None

