"""The one resolver of ``module:Attr`` plug-in strings (agents, env factories, training env
classes, highway-env classes): one way to import them, one set of error messages."""

from __future__ import annotations

import importlib

from hbmp_bench.errors import UserError, raised_at


def described(exc: BaseException) -> str:
    """``Type: message (at file:line)``: a plug-in's own failure in one line."""
    where = "" if isinstance(exc, SyntaxError) else raised_at(exc)  # a SyntaxError names its file and line
    return f"{type(exc).__name__}: {exc}" + (f" (at {where})" if where else "")


def resolve(spec: str, what: str) -> object:
    """The attribute named by ``spec`` (``package.module:Attr``); ``what`` names it in errors.

    Raises:
        UserError: ``spec`` is not ``module:Attr``, the module does not import (or its own code
            raises while importing), or it lacks the attribute; the original exception is the
            ``__cause__``.
    """
    module_name, colon, attr = spec.partition(":")
    if not colon or not module_name or not attr:
        raise UserError(f"cannot load {what} {spec!r}: want 'module:Attr'")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise UserError(f"cannot load {what} {spec!r}: {exc}") from exc
    except Exception as exc:  # noqa: BLE001 - the plug-in module's own code failed
        raise UserError(f"cannot load {what} {spec!r}: importing {module_name} raised {described(exc)}") from exc
    try:
        return getattr(module, attr)
    except AttributeError as exc:
        raise UserError(f"cannot load {what} {spec!r}: {exc}") from exc
