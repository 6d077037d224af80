"""An agent's options, typed: their names and types, checked before anything is played.

The options are the keyword parameters of ``__init__`` plus the fields of the agent's
``config_class``. :func:`check_options` verifies given values; :func:`parse_options` turns
command-line ``key=value`` strings into typed values.
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import os
import types
import typing
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any


class AgentOptionError(ValueError):
    """An agent option that the agent does not have, or a value of the wrong type."""


def _hints(obj: Any) -> dict[str, Any]:
    try:
        return typing.get_type_hints(obj)
    except Exception:  # unresolved forward references: fall back to no type
        return {}


def _unpacked_keys(hint: Any) -> dict[str, Any] | None:
    """The keys and types of ``**kwargs: Unpack[SomeTypedDict]``; None for untyped kwargs."""
    args = typing.get_args(hint) if hint is not None else ()
    if len(args) != 1 or not typing.is_typeddict(args[0]):
        return None
    return _hints(args[0])


def agent_options(cls: type) -> dict[str, Any]:
    """Option names of an agent class and their annotated types (``Any`` when untyped)."""
    options: dict[str, Any] = {}
    init = cls.__init__
    accepts_any = False
    if init is not object.__init__:
        hints = _hints(init)
        for name, param in inspect.signature(init).parameters.items():
            if name == "self" or param.kind is param.VAR_POSITIONAL:
                continue
            if param.kind is param.VAR_KEYWORD:
                typed = _unpacked_keys(hints.get(name))
                if typed is None:
                    accepts_any = True
                else:
                    options.update(typed)
                continue
            options[name] = hints.get(name, Any)
    config = getattr(cls, "config_class", None)
    if config is not None and dataclasses.is_dataclass(config):
        hints = _hints(config)
        for item in dataclasses.fields(config):
            if item.init:
                options[item.name] = hints.get(item.name, Any)
    elif accepts_any:
        options["**"] = Any
    return options


def _type_name(tp: Any) -> str:
    if tp is Any:
        return "any"
    if isinstance(tp, type):
        return tp.__name__
    return str(tp).replace("typing.", "")


def conforms(value: Any, tp: Any) -> bool:
    """Whether ``value`` is acceptable for the annotation ``tp`` (lenient where unsure)."""
    if tp is Any or tp is object:
        return True
    if tp is None or tp is type(None):
        return value is None
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        return any(conforms(value, arg) for arg in args)
    if origin is typing.Literal:
        return value in args
    if tp is bool:
        return isinstance(value, bool)
    if tp is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if tp is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if tp is str:
        return isinstance(value, str)
    if tp in (Path, os.PathLike) or origin is os.PathLike:
        return isinstance(value, (str, os.PathLike))
    if origin in (tuple, list, Sequence, typing.Sequence) or tp in (tuple, list):
        if not isinstance(value, (tuple, list)):
            return False
        if origin is tuple and args and args[-1] is not Ellipsis:
            return len(value) == len(args) and all(map(conforms, value, args))
        return not args or all(conforms(item, args[0]) for item in value)
    if origin in (dict, Mapping) or tp in (dict, Mapping):
        return isinstance(value, Mapping)
    if origin is Callable or tp is Callable:
        return callable(value)
    if isinstance(tp, type):
        return isinstance(value, tp)
    return True  # an annotation we do not interpret: accept


def _describe(options: dict[str, Any]) -> str:
    return ", ".join(f"{name} ({_type_name(tp)})" for name, tp in sorted(options.items())
                     if name != "**")


def check_options(cls: type, kwargs: Mapping[str, Any], *, agent: str | None = None,
                  kind: str = "agent", extra: Mapping[str, Any] | None = None) -> None:
    """Raise :class:`AgentOptionError` for an unknown option or a value of the wrong type.

    ``kind`` names what is checked in messages (``"agent"``, ``"environment"``); ``extra``
    adds options that something other than the class accepts (e.g. ``gym.make``'s own).
    """
    options = agent_options(cls) | dict(extra or {})
    label = agent or getattr(cls, "name", "") or cls.__qualname__
    for key, value in kwargs.items():
        if key not in options:
            if "**" in options:
                continue
            raise AgentOptionError(
                f"{kind} '{label}' has no option '{key}'; valid options: {_describe(options)}"
            )
        if not conforms(value, options[key]):
            raise AgentOptionError(
                f"{kind} '{label}' option '{key}' must be {_type_name(options[key])}, "
                f"got {value!r} ({type(value).__name__})"
            )
    _check_values(cls, kwargs, label, kind)


def _check_values(cls: type, kwargs: Mapping[str, Any], label: str, kind: str) -> None:
    """Build the agent's ``config_class`` from its options: its checks of the values run now.

    So a value out of range (``duplicate_iou=1.5``) stops the run before anything is built or
    played, with the config's own message; the agent builds the same config again.
    """
    config = getattr(cls, "config_class", None)
    if config is None or not dataclasses.is_dataclass(config):
        return
    names = {item.name for item in dataclasses.fields(config) if item.init}
    try:
        config(**{key: value for key, value in kwargs.items() if key in names})
    except (ValueError, TypeError) as exc:
        raise AgentOptionError(f"{kind} '{label}': {exc}") from None


def parse_options(cls: type, items: Sequence[str], *, agent: str | None = None,
                  kind: str = "agent", extra: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Parse ``key=value`` strings into the agent's typed options, checked.

    A value is read as a Python literal (``0.5``, ``(640, 480)``, ``None``, ``True``) when
    that fits the option's type; an option that takes a string or a path gets the text as
    written, so ``weights=moco.pth`` needs no quotes.
    """
    options = agent_options(cls) | dict(extra or {})
    out: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        key = key.strip().replace("-", "_")
        if not sep or not key:
            raise AgentOptionError(f"{kind} option '{item}' must look like key=value")
        tp = options.get(key, options.get("**", Any))
        try:
            value: Any = ast.literal_eval(text)
        except (ValueError, SyntaxError):
            value = text
        if key in options and not conforms(value, tp) and conforms(text, tp):
            value = text
        out[key] = value
    check_options(cls, out, agent=agent, kind=kind, extra=extra)
    return out
