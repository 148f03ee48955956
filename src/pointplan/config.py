"""Configuration dataclasses: rebuilt from saved dicts, turned into command-line options.

The dataclasses (``TrainConfig``, ``SACConfig``, ``NetConfig``, ``BCConfig``, ...) are the one
source of the defaults and of their documentation (the ``#:`` comment above a field, or
``field(metadata={"help": ...})``); the command line derives its options from them and
applies what was given with :func:`replace_paths`.
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import re
import types
import typing
from functools import cache
from typing import Any, TypeVar

T = TypeVar("T")


def _dataclass_of(hint: Any) -> type | None:
    """The dataclass in a type hint (``X`` or ``X | None``), or None."""
    if dataclasses.is_dataclass(hint) and isinstance(hint, type):
        return hint
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        inner = [a for a in typing.get_args(hint) if a is not type(None)]
        return _dataclass_of(inner[0]) if len(inner) == 1 else None
    return None


def from_dict(cls: type[T], data: dict[str, Any]) -> T:
    """``cls`` (a dataclass) from a plain dict as ``to_dict`` wrote it, nested dataclasses
    included; fields missing from ``data`` take their defaults."""
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(data) - names)
    if unknown:
        raise ValueError(f"unknown {cls.__name__} settings: {', '.join(unknown)}")
    kwargs: dict[str, Any] = {}
    for name, value in data.items():
        inner = _dataclass_of(hints[name])
        kwargs[name] = from_dict(inner, value) if inner is not None and isinstance(value, dict) else value
    return cls(**kwargs)


@cache
def field_docs(cls: type) -> dict[str, str]:
    """The ``#:`` comments above the fields of ``cls`` (and its dataclass bases)."""
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if not dataclasses.is_dataclass(klass):
            continue
        try:
            lines = inspect.getsource(klass).splitlines()
        except (OSError, TypeError):
            continue
        pending: list[str] = []
        for line in lines:
            text = line.strip()
            if text.startswith("#:"):
                pending.append(text[2:].strip())
                continue
            m = re.match(r"(\w+)\s*:", text)
            if m and pending:
                docs[m.group(1)] = " ".join(pending)
            pending = []
    for f in dataclasses.fields(cls):
        if "help" in f.metadata:
            docs[f.name] = str(f.metadata["help"])
    return docs


def _scalar_type(hint: Any) -> type:
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        hint = next(a for a in typing.get_args(hint) if a is not type(None))
    if hint not in (int, float, str, bool):
        raise TypeError(f"no command-line option for a field of type {hint}")
    return typing.cast(type, hint)


def _get_path(obj: Any, path: str) -> Any:
    for part in path.split("."):
        obj = getattr(obj, part)
    return obj


def _field_hint(cls: type, path: str) -> tuple[Any, str, dict[str, Any]]:
    """The type hint, the documentation and the metadata of the field at dotted ``path``."""
    head, _, rest = path.partition(".")
    hint = typing.get_type_hints(cls)[head]
    if rest:
        inner = _dataclass_of(hint)
        if inner is None:
            raise ValueError(f"{cls.__name__}.{head} is not a dataclass")
        return _field_hint(inner, rest)
    meta = next(f.metadata for f in dataclasses.fields(cls) if f.name == head)  # type: ignore[arg-type]
    return hint, field_docs(cls).get(head, ""), dict(meta)


def _at_least(kind: type, low: float) -> Any:
    """An argparse type: a number of ``kind`` no smaller than ``low``."""

    def parse(text: str) -> Any:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected {'an integer' if kind is int else 'a number'}, got {text!r}"
            ) from None
        if value < low:
            raise argparse.ArgumentTypeError(f"must be at least {kind(low)}, got {value}")
        return value

    parse.__name__ = kind.__name__  # argparse names the type in its messages
    return parse


def add_config_options(parser: argparse.ArgumentParser, defaults: Any, paths: dict[str, str]) -> None:
    """Add ``--flag`` options for fields of the dataclass instance ``defaults``.

    ``paths`` maps each flag (without dashes) to a dotted field path (``"lr": "sac.lr"``).
    Types, help and the default shown come from the dataclass (integers are at least 0, or
    at least ``field(metadata={"min": ...})``; ``metadata={"choices": (...)}`` limits the
    values); the parsed value is ``None`` when the
    option is not given, so :func:`given_options` sees what the user set.
    """
    for flag, path in paths.items():
        hint, doc, meta = _field_hint(type(defaults), path)
        kind = _scalar_type(hint)
        parse: Any = kind
        if "min" in meta or kind is int:
            parse = _at_least(kind, meta.get("min", 0))
        default = _get_path(defaults, path)
        text = doc.replace("``", "") if doc else path.replace("_", " ")
        text = text.replace("%", "%%") + f" (default: {default})"
        if kind is bool:
            parser.add_argument(f"--{flag}", dest=path, action=argparse.BooleanOptionalAction, default=None, help=text)
        else:
            choices = meta.get("choices")
            metavar = "{" + ",".join(choices) + "}" if choices else flag.upper().replace("-", "_")
            parser.add_argument(
                f"--{flag}", dest=path, type=parse, default=None, choices=choices, metavar=metavar, help=text
            )


def given_options(args: argparse.Namespace, paths: dict[str, str]) -> dict[str, Any]:
    """The field paths of ``paths`` that were given on the command line, with their values."""
    return {path: getattr(args, path) for path in paths.values() if getattr(args, path, None) is not None}


def replace_paths(cfg: T, values: dict[str, Any]) -> T:
    """A copy of the dataclass ``cfg`` with the fields at dotted paths replaced
    (``{"total_steps": 10, "sac.lr": 1e-4}``), through ``dataclasses.replace``."""
    top: dict[str, Any] = {}
    nested: dict[str, dict[str, Any]] = {}
    for path, value in values.items():
        head, _, rest = path.partition(".")
        if rest:
            nested.setdefault(head, {})[rest] = value
        else:
            top[head] = value
    for head, inner in nested.items():
        top[head] = replace_paths(getattr(cfg, head), inner)
    return dataclasses.replace(cfg, **top)  # type: ignore[type-var]
