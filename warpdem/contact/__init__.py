"""Composable contact laws. Importing this package registers the built-in sub-models."""
from . import hertz_mindlin, none, rolling  # noqa: F401  (registration side effects)
from .base import KINDS, PAIR_TYPES, REGISTRY, ContactInput, ParameterSpec, SubModel, available, register
from .law import ContactLaw

__all__ = [
    "KINDS", "PAIR_TYPES", "REGISTRY", "ContactInput", "ParameterSpec", "SubModel", "available", "register",
    "ContactLaw",
]
