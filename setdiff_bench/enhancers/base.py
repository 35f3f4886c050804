"""The enhancer interface and registry.

An enhancer receives a :class:`~setdiff_bench.types.Packet` — N clean references and M rendered
targets with C-maps and normalised cameras — and returns the M enhanced targets.  Ground truth and
masks never reach it.

Registry entries are lazy ``"module:attr"`` specs, so listing methods imports nothing heavy.  The
built-ins are below; third parties add theirs through the entry-point group
``setdiff_bench.enhancers`` (each entry point names a :class:`MethodSpec` or a factory returning one).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from importlib import metadata
from typing import Any, Protocol, runtime_checkable

import torch

from setdiff_bench.errors import UsageError
from setdiff_bench.types import Packet

ENTRY_POINT_GROUP = "setdiff_bench.enhancers"


@runtime_checkable
class Enhancer(Protocol):
    """What every method implements."""

    name: str

    def enhance(self, packet: Packet) -> torch.Tensor:
        """Return ``(M, 3, H, W)`` float32 images in [0, 1], one per target view, in packet order."""
        ...


@dataclass(frozen=True)
class MethodSpec:
    """A registered method.

    Attributes:
        name: the ``--method`` key.
        factory: ``"module:attr"`` of a callable ``factory(**options) -> Enhancer``.
        description: one line for ``setdiff-bench list methods``.
        needs_weights: whether it needs a checkpoint or pretrained weights.
        needs_gpu: whether it is impractical without CUDA.
        options: default keyword options passed to the factory.
    """

    name: str
    factory: str
    description: str
    needs_weights: bool = False
    needs_gpu: bool = False
    options: Mapping[str, Any] = field(default_factory=dict)

    def load_factory(self) -> Callable[..., Enhancer]:
        module_name, _, attr = self.factory.partition(":")
        module = importlib.import_module(module_name)
        return getattr(module, attr)


BUILTIN_METHODS: dict[str, MethodSpec] = {}


def register_builtin(spec: MethodSpec) -> None:
    """Add a built-in method (called at import of this module's bottom section)."""
    BUILTIN_METHODS[spec.name] = spec


def available_methods() -> dict[str, MethodSpec]:
    """Built-in methods plus entry-point plugins (a plugin may not shadow a built-in name)."""
    methods = dict(BUILTIN_METHODS)
    for entry in metadata.entry_points(group=ENTRY_POINT_GROUP):
        if entry.name in methods:
            continue
        spec = entry.load()
        if callable(spec) and not isinstance(spec, MethodSpec):
            spec = spec()
        if not isinstance(spec, MethodSpec):
            raise UsageError(f"entry point {entry.name!r} of group {ENTRY_POINT_GROUP} is not a MethodSpec",
                             entry.value)
        methods[spec.name] = spec
    return methods


def create_enhancer(name: str, **options: Any) -> Enhancer:
    """Instantiate the method called ``name`` with the spec's default options updated by ``options``."""
    methods = available_methods()
    if name not in methods:
        raise UsageError(f"unknown method {name!r}; available: {', '.join(sorted(methods))}", "--method")
    spec = methods[name]
    merged = {**spec.options, **{k: v for k, v in options.items() if v is not None}}
    enhancer = spec.load_factory()(**merged)
    if not isinstance(enhancer, Enhancer):
        raise UsageError(f"method {name!r} did not build an Enhancer (got {type(enhancer).__name__})", spec.factory)
    return enhancer


# Built-in learned methods (lazy specs: listing them imports nothing heavy).
register_builtin(MethodSpec(
    name="setdiff", factory="setdiff_bench.enhancers.setdiff:create",
    description="SetDiff: geometry-grounded set diffusion over all references + targets (--checkpoint CKPT)",
    needs_weights=True))
register_builtin(MethodSpec(
    name="difix", factory="setdiff_bench.enhancers.difix:create",
    description="DiFix3D-style baseline: best reference + one target, RGB only (--checkpoint CKPT)",
    needs_weights=True))
