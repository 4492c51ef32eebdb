"""Composable contact laws and the discovery of their sub-models.

Sub-models register themselves (:func:`register`) when their module is imported. Importing
this package imports, without a hand-kept list:

1. every module of this folder (``warpdem/contact/*.py``), so a new built-in effect is one file;
2. every module named by an installed distribution's entry point in the group
   ``warpdem.contact_models`` (see :func:`discover_plugins`); a broken plugin is reported with
   a :class:`ContactPluginWarning` naming it, the others still load.

User files or modules of sub-models that are not installed (a config's ``plugins:`` list) are
imported with :func:`load_module`. See ``docs/adding_an_effect.md``.
"""
from __future__ import annotations

import hashlib
import importlib
import importlib.metadata
import importlib.util
import os
import pkgutil
import sys
import warnings
from pathlib import Path
from types import ModuleType

from ..errors import ConfigError
from .base import KINDS, PAIR_TYPES, REGISTRY, ContactInput, ParameterSpec, SubModel, available, register
from .law import ContactLaw

__all__ = [
    "KINDS", "PAIR_TYPES", "REGISTRY", "ContactInput", "ParameterSpec", "SubModel", "available", "register",
    "ContactLaw", "ENTRY_POINT_GROUP", "ContactPluginWarning", "discover_plugins", "load_module",
]

ENTRY_POINT_GROUP = "warpdem.contact_models"


class ContactPluginWarning(RuntimeWarning):
    """An installed contact-model plugin (entry point) failed to load."""


def _import_package_modules() -> list[str]:
    """Import every module of this folder (built-in sub-models register on import)."""
    names = []
    for info in pkgutil.iter_modules(__path__):
        if info.name.startswith("_"):
            continue
        importlib.import_module(f"{__name__}.{info.name}")
        names.append(info.name)
    return names


def discover_plugins(group: str = ENTRY_POINT_GROUP) -> list[str]:
    """Import the sub-model plugins of installed distributions; returns the loaded entry points.

    A plugin declares, in its ``pyproject.toml``::

        [project.entry-points."warpdem.contact_models"]
        my_effects = "my_package.my_effects"          # a module: importing it registers

    (``"my_package.my_effects:MyCohesion"`` naming a :class:`SubModel` class also works; the
    class is registered.) A plugin that fails to import gives a :class:`ContactPluginWarning`
    naming the entry point, its target and distribution, and the error; it is skipped.
    Called once when :mod:`warpdem.contact` is imported; call again after installing a plugin
    in a running interpreter (re-imports are harmless: registration is idempotent).
    """
    loaded = []
    for ep in importlib.metadata.entry_points(group=group):
        dist = getattr(getattr(ep, "dist", None), "name", None) or "unknown distribution"
        try:
            obj = ep.load()
            if isinstance(obj, type) and issubclass(obj, SubModel):
                register(obj)
            elif not isinstance(obj, ModuleType):
                raise ConfigError(f"entry point names {type(obj).__name__} {obj!r}, expected a module or a SubModel class")
        except Exception as exc:  # noqa: BLE001 - a broken plugin must not break warpdem
            warnings.warn(
                f"warpdem contact-model plugin '{ep.name}' = '{ep.value}' (from {dist}, entry-point group "
                f"'{group}') failed to load and is skipped: {type(exc).__name__}: {exc}",
                ContactPluginWarning,
                stacklevel=2,
            )
            continue
        loaded.append(f"{ep.name} = {ep.value}")
    return loaded


def _module_name_for_file(path: Path) -> str:
    """A stable, unique module name for a user file (same file -> same name -> idempotent)."""
    digest = hashlib.sha1(str(path).encode()).hexdigest()[:10]
    stem = "".join(ch if ch.isalnum() else "_" for ch in path.stem)
    return f"warpdem_plugin_{stem}_{digest}"


def load_module(path_or_module_name: str | os.PathLike, relative_to: str | os.PathLike | None = None) -> ModuleType:
    """Import a user file or module of contact sub-models (their ``@register`` runs).

    Args:
        path_or_module_name: a ``.py`` file (a ``Path``, or a string ending in ``.py`` or
            containing a path separator), or an importable dotted module name
            (``"my_package.my_effects"``).
        relative_to: folder a relative file path is taken from (e.g. the config's folder);
            default: the working directory.

    Returns the module. Loading the same file again returns the module already loaded.

    Raises:
        ConfigError: the file or module does not exist, or importing it failed (the error
            names the file and the original exception).
    """
    target = path_or_module_name
    as_text = os.fspath(target)
    is_file = isinstance(target, os.PathLike) or as_text.endswith(".py") or os.sep in as_text or "/" in as_text
    if not is_file:
        if not as_text or not all(part.isidentifier() for part in as_text.split(".")):
            raise ConfigError(f"contact plugin {as_text!r} is neither a .py file nor a dotted module name")
        try:
            return importlib.import_module(as_text)
        except ModuleNotFoundError as exc:
            if exc.name and as_text.startswith(exc.name):
                raise ConfigError(f"contact plugin module '{as_text}' not found (not installed or not on sys.path)") from exc
            raise ConfigError(f"contact plugin module '{as_text}' failed to import: {exc}") from exc
        except ConfigError:
            raise
        except Exception as exc:
            raise ConfigError(f"contact plugin module '{as_text}' failed to import: {type(exc).__name__}: {exc}") from exc

    path = Path(as_text)
    if not path.is_absolute() and relative_to is not None:
        path = Path(relative_to) / path
    path = path.resolve()
    if not path.is_file():
        raise ConfigError(f"contact plugin file not found: {path}")
    if path.suffix != ".py":
        raise ConfigError(f"contact plugin file must be a .py file: {path}")
    name = _module_name_for_file(path)
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:  # pragma: no cover - .py files always have a loader
        raise ConfigError(f"contact plugin file {path} cannot be imported")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # before exec: dataclasses and pickling look the module up
    try:
        spec.loader.exec_module(module)
    except ConfigError as exc:
        del sys.modules[name]
        raise ConfigError(f"contact plugin file {path}: {exc}") from exc
    except Exception as exc:
        del sys.modules[name]
        raise ConfigError(f"contact plugin file {path} failed to import: {type(exc).__name__}: {exc}") from exc
    return module


BUILTIN_MODULES = tuple(_import_package_modules())
discover_plugins()
