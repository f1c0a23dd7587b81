"""Descriptor registry: name -> model class, loaded lazily.

Importing this package is cheap (no torch): a model's module is imported only
when that model is asked for by ``get`` or ``defaults_for``.
"""

from __future__ import annotations

import importlib

from ..errors import InputError
from .base import DescriptorModel, Descriptors

DEFAULT_DESCRIPTOR = "effnet-vlad"

# name -> "module:Class"
REGISTRY: dict[str, str] = {
    "effnet-vlad": "engine.descriptors.efficientnet:EfficientNetVLAD",
    "anyloc-vlad": "engine.descriptors.anyloc:AnyLocVLAD",
    "anyloc-gem": "engine.descriptors.anyloc:AnyLocGeM",
    "megaloc": "engine.descriptors.megaloc:MegaLoc",
    "boq": "engine.descriptors.boq:BoQ",
}

__all__ = [
    "DEFAULT_DESCRIPTOR",
    "REGISTRY",
    "DescriptorModel",
    "Descriptors",
    "defaults_for",
    "get",
    "model_class",
    "names",
]


def names() -> list[str]:
    """Registered descriptor names, the default first."""
    return [DEFAULT_DESCRIPTOR] + sorted(n for n in REGISTRY if n != DEFAULT_DESCRIPTOR)


def model_class(name: str) -> type[DescriptorModel]:
    """The class registered as ``name`` (imports its module)."""
    if name not in REGISTRY:
        raise InputError(f"unknown descriptor '{name}'; choose one of: {', '.join(names())}")
    module_name, class_name = REGISTRY[name].split(":")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise InputError(f"descriptor '{name}' is not available here ({exc})") from None
    return getattr(module, class_name)


def get(name: str, **options) -> DescriptorModel:
    """A ready model ``name`` built with ``options`` (unknown name -> InputError)."""
    cls = model_class(name)
    try:
        return cls(**options)
    except TypeError as exc:
        raise InputError(f"descriptor '{name}': bad option ({exc})") from None


def defaults_for(name: str) -> dict:
    """Calibrated map parameters of descriptor ``name``, without building the model."""
    return dict(model_class(name).defaults)
