"""The enhancer interface and registry.

An enhancer receives a :class:`~setdiff_bench.types.Packet` — N clean references and M rendered
targets with C-maps and normalised cameras — and returns the M enhanced targets.  Ground truth and
masks never reach it.

Registry entries are lazy ``"module:attr"`` specs (:class:`MethodSpec`), so listing methods imports
nothing heavy: the built-ins are declared as data in :data:`BUILTIN_METHODS`, and their modules are
imported only by :meth:`MethodSpec.load_factory` when a method is actually built.  Third parties add
methods through the entry-point group ``setdiff_bench.enhancers``; each entry point names a
:class:`MethodSpec`, or a zero-argument callable returning one.  For example, in a plugin's
``pyproject.toml``::

    [project.entry-points."setdiff_bench.enhancers"]
    mymethod = "my_package.setdiff_spec:SPEC"

where ``SPEC = MethodSpec(name="mymethod", factory="my_package.method:create", description="...")``.
A plugin may not shadow a built-in name or another plugin's name: the first definition wins and the
duplicate is reported with a :class:`RegistryWarning`.
"""

from __future__ import annotations

import inspect
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from importlib import metadata
from types import MappingProxyType
from typing import Any, Protocol, runtime_checkable

import torch

from setdiff_bench.errors import UsageError
from setdiff_bench.runtime.lazy import load_attribute
from setdiff_bench.types import Packet, TargetRef

ENTRY_POINT_GROUP = "setdiff_bench.enhancers"


class MethodOptionError(UsageError):
    """A method was given options its factory does not take.

    The message names each option as the caller spells it: a Python caller reads the factory's keywords
    (``method 'identity' does not take source (it takes: no options)``); the command line, which passes
    the verb's ``{dest: option}`` spelling to :meth:`one_line`, reads its flags
    (``--method: method 'identity' does not take --from (it takes: no options)``), and a key that is no
    flag of the verb (given with ``-o key=value``) by its name.

    Args:
        method: the registry key of the method.
        unknown: the options given that the factory does not take, sorted.
        accepted: the options the factory takes, sorted.
    """

    def __init__(self, method: str, unknown: Sequence[str], accepted: Sequence[str]) -> None:
        self.method = method
        self.unknown = tuple(unknown)
        self.accepted = tuple(accepted)
        super().__init__(self.describe(None), parameter="method")

    def describe(self, options: Mapping[str, str] | None) -> str:
        """The problem with each option spelled by ``options`` (``{dest: flag}``) where it has one."""

        def spell(key: str) -> str:
            return (options or {}).get(key) or key

        takes = ", ".join(spell(key) for key in self.accepted) or "no options"
        return f"method {self.method!r} does not take {', '.join(spell(k) for k in self.unknown)} (it takes: {takes})"

    def one_line(self, options: Mapping[str, str] | None = None) -> str:
        """``where: problem`` as :meth:`SetDiffBenchError.one_line`, the options spelled by ``options``."""
        where = self.where(options)
        problem = self.describe(options)
        return f"{where}: {problem}" if where else problem


class RegistryWarning(UserWarning):
    """A plugin entry point was skipped (duplicate name)."""


@runtime_checkable
class Enhancer(Protocol):
    """What every method implements.

    Optional extras the runner uses when present: ``options`` (a JSON-serialisable mapping recorded in
    the run manifest) and ``check_targets(targets)`` (see :class:`ChecksTargets`).
    """

    name: str

    def enhance(self, packet: Packet) -> torch.Tensor:
        """Return ``(M, 3, H, W)`` float32 images in [0, 1], one per target view, in packet order."""
        ...


def enhancer_repr(enhancer: object, **shown: object) -> str:
    """The short repr every built-in enhancer uses: ``SetDiffEnhancer('setdiff', checkpoint='tiny_setdiff',
    device='cpu')`` — the class, the method name, then ``shown`` (what identifies the built method: its checkpoint,
    its images folder, options that differ from the defaults), ``None`` values left out.  A plugin may use it
    too."""
    parts = [repr(getattr(enhancer, "name", "?"))]
    parts += [f"{key}={value!r}" for key, value in shown.items() if value is not None]
    return f"{type(enhancer).__name__}({', '.join(parts)})"


@runtime_checkable
class ChecksTargets(Protocol):
    """An enhancer that can verify up front that it can serve every target of a run.

    The runner calls ``check_targets`` once, before enhancing anything, with every target of the
    selected packets; it raises a :class:`~setdiff_bench.errors.SetDiffBenchError` listing what is
    missing (e.g. ``precomputed`` images that were never produced).
    """

    def check_targets(self, targets: Sequence[TargetRef]) -> None: ...


@runtime_checkable
class EstimatesMemory(Protocol):
    """An enhancer that can say, before it runs, how much memory a packet of a given shape takes.

    Attributes:
        device: the torch device it computes on (``cpu``, ``cuda:0``).
    """

    device: str

    def memory_bytes(self, references: int, targets: int, height: int, width: int) -> int:
        """Estimated peak bytes above the loaded enhancer to enhance N references + M targets of H × W."""
        ...


@runtime_checkable
class KnowsTrainingData(Protocol):
    """An enhancer whose training data is recorded, so that it can tell when it meets other data."""

    def out_of_distribution(
        self, datasets: Sequence[str], resolutions: Sequence[tuple[int, int]], what: str
    ) -> str | None:
        """One warning line when ``datasets`` / ``(height, width)`` ``resolutions`` differ from its training
        data (``what`` names them: ``this store``), else ``None``."""
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
        source: ``"builtin"``, or the entry point (``name = value``) a plugin came from.
        fingerprint: ``"module:attr"`` of a callable ``fingerprint(**options) -> {file name: SHA-256}`` naming
            the content of the files (weights, config) that decide the method's outputs for these options,
            without building the method; ``run`` records it in ``run.json`` so that a resume with other
            weights behind the same option (a retrained or re-exported checkpoint) is refused.
    """

    name: str
    factory: str
    description: str
    needs_weights: bool = False
    needs_gpu: bool = False
    options: Mapping[str, Any] = field(default_factory=dict)
    source: str = "builtin"
    fingerprint: str | None = None

    def load_factory(self) -> Callable[..., Enhancer]:
        """Import the factory (this is where a method's heavy imports happen)."""
        return load_attribute(
            self.factory, f"method {self.name!r} factory", error=UsageError, path=self.source
        )

    def model_files(self, options: Mapping[str, Any]) -> dict[str, str]:
        """``{file name: SHA-256}`` of what decides the outputs for ``options`` (empty without a fingerprint)."""
        if self.fingerprint is None:
            return {}
        function = load_attribute(
            self.fingerprint, f"method {self.name!r} fingerprint", error=UsageError, path=self.source
        )
        return dict(function(**options))


#: Fingerprint of the methods that load a trained checkpoint (``setdiff`` and ``difix`` share one loader).
CHECKPOINT_FINGERPRINT = "setdiff_bench.enhancers.setdiff:fingerprint"


def _builtin(
    name: str, module: str, description: str, needs_weights: bool = False, fingerprint: str | None = None
) -> MethodSpec:
    return MethodSpec(
        name=name,
        factory=f"setdiff_bench.enhancers.{module}:create",
        description=description,
        needs_weights=needs_weights,
        fingerprint=fingerprint,
    )


#: The built-in methods, declared as data (nothing is imported to list them).
BUILTIN_METHODS: dict[str, MethodSpec] = {
    spec.name: spec
    for spec in (
        _builtin("identity", "identity", "the raw 3DGS render unchanged (the paper's '3DGS' / 'OmniRe' row)"),
        _builtin(
            "reproject",
            "reproject",
            "geometry-only baseline: reference colours reprojected through C-maps with a depth test, Eq. 2 blend",
        ),
        _builtin(
            "precomputed",
            "precomputed",
            "score images produced by external code (--from DIR, matched by frame name)",
        ),
        _builtin(
            "setdiff",
            "setdiff",
            "SetDiff: geometry-grounded set diffusion over all references + targets (--checkpoint CKPT)",
            needs_weights=True,
            fingerprint=CHECKPOINT_FINGERPRINT,
        ),
        _builtin(
            "difix",
            "difix",
            "DiFix3D-style baseline: nearest-pose reference + one target, RGB only (--checkpoint CKPT)",
            needs_weights=True,
            fingerprint=CHECKPOINT_FINGERPRINT,
        ),
    )
}


def register_builtin(spec: MethodSpec) -> None:
    """Add (or replace) a built-in method spec; later lookups see it."""
    BUILTIN_METHODS[spec.name] = spec


def _plugin_spec(entry: metadata.EntryPoint) -> MethodSpec:
    where = f"entry point {entry.name} = {entry.value} (group {ENTRY_POINT_GROUP})"
    try:
        spec = entry.load()
        if callable(spec) and not isinstance(spec, MethodSpec):
            spec = spec()
    except Exception as error:  # a broken plugin must say which one, in one line
        raise UsageError(f"cannot load plugin method: {type(error).__name__}: {error}", where) from None
    if not isinstance(spec, MethodSpec):
        raise UsageError(f"plugin method is a {type(spec).__name__}, expected a MethodSpec", where)
    # every field of the plugin's spec is kept (its fingerprint included, so that a resume with other weights
    # is refused as for the built-ins); only the options are frozen and the source names the entry point
    return replace(spec, options=MappingProxyType(dict(spec.options)), source=f"{entry.name} = {entry.value}")


def available_methods() -> dict[str, MethodSpec]:
    """Built-in methods plus entry-point plugins, built-ins first, plugins sorted by entry-point name.

    Raises:
        UsageError: a plugin entry point cannot be imported or does not give a MethodSpec.
    """
    methods = dict(BUILTIN_METHODS)
    entries = sorted(metadata.entry_points(group=ENTRY_POINT_GROUP), key=lambda e: (e.name, e.value))
    for entry in entries:
        spec = _plugin_spec(entry)
        if spec.name in methods:
            warnings.warn(
                f"plugin {spec.source!r} defines method {spec.name!r}, already defined by "
                f"{methods[spec.name].source!r}; ignored",
                RegistryWarning,
                stacklevel=2,
            )
            continue
        methods[spec.name] = spec
    return methods


def factory_parameters(factory: Callable[..., Any]) -> tuple[set[str], bool]:
    """Keyword names a factory accepts, and whether it takes ``**kwargs``."""
    try:
        signature = inspect.signature(factory)
    except (TypeError, ValueError):
        return set(), True
    names = {
        p.name
        for p in signature.parameters.values()
        if p.kind in (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    }
    var_kw = any(p.kind == inspect.Parameter.VAR_KEYWORD for p in signature.parameters.values())
    return names, var_kw


def create_enhancer(name: str, *, optional: Mapping[str, Any] | None = None, **options: Any) -> Enhancer:
    """Instantiate the method called ``name``.

    Args:
        name: registry key (``setdiff-bench list methods``).
        optional: options passed only when the factory accepts them (e.g. the runner's ``device``);
            ``None`` values are dropped.
        **options: options the factory must accept (a ``UsageError`` names any it does not);
            ``None`` values are dropped, the rest update the spec's default options.

    Raises:
        UsageError: unknown method, an option the method does not take (:class:`MethodOptionError`), or a
            factory that does not return an :class:`Enhancer`.
    """
    methods = available_methods()
    if name not in methods:
        raise UsageError(
            f"unknown method {name!r}; available: {', '.join(sorted(methods))}", parameter="method"
        )
    spec = methods[name]
    factory = spec.load_factory()
    accepted, var_kw = factory_parameters(factory)
    given = {k: v for k, v in options.items() if v is not None}
    unknown = sorted(k for k in given if k not in accepted and not var_kw)
    if unknown:
        raise MethodOptionError(name, unknown, sorted(accepted))
    extra = {k: v for k, v in (optional or {}).items() if v is not None and (k in accepted or var_kw)}
    merged = {**spec.options, **extra, **given}
    enhancer = factory(**merged)
    if not isinstance(enhancer, Enhancer):
        raise UsageError(
            f"method {name!r} did not build an Enhancer (got {type(enhancer).__name__})", spec.factory
        )
    return enhancer
