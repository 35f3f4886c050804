"""The settings of a 3DGS fit (:class:`FitConfig`): iterations, learning rates, SH schedule, initialisation
and the densification strategy, with the standard schedule compressed to any length, rescaling, and the
JSON form a checkpoint stores (either shape: nested ``"strategy"`` or the older flat keys).

Iterations are 1-based as in Inria; positions are in world units (learning rate × scene extent).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field

from setdiff_bench.errors import UsageError
from setdiff_bench.gaussians.densify import DensificationStrategy


@dataclass(frozen=True)
class FitConfig:
    """Hyper-parameters; defaults are the Inria 3DGS values for a 30 000-iteration run.

    Learning rates (Adam): ``lr_means`` (× scene extent, decayed to ``lr_means_final`` × extent over
    ``iterations``), ``lr_sh_dc``, ``lr_sh_rest`` (= dc / 20), ``lr_opacity`` (0.05, the original 3DGS
    release and gsplat's default; later Inria versions use 0.025), ``lr_scales``, ``lr_quats``.
    Density control: ``strategy``, a :class:`~setdiff_bench.gaussians.densify.DensificationStrategy`
    that holds its thresholds and schedule (iterations are 1-based as in Inria); it also caps the
    random initialisation at half its ``max_gaussians``.

    ``background_points`` (0 = off, the Inria behaviour) adds that many points on a sphere of
    ``background_radius`` × extent around the cameras, coloured from the training images: SfM leaves
    the sky empty, and a short fit cannot grow Gaussians that far out (street-scene 3DGS methods add a
    similar sky/background initialisation).
    """

    iterations: int = 30_000
    sh_degree: int = 3
    sh_increase_every: int = 1000
    lr_means: float = 1.6e-4
    lr_means_final: float = 1.6e-6
    lr_means_delay_mult: float = 0.01
    lr_sh_dc: float = 2.5e-3
    lr_sh_rest: float = 2.5e-3 / 20
    lr_opacity: float = 0.05
    lr_scales: float = 5e-3
    lr_quats: float = 1e-3
    lambda_dssim: float = 0.2
    strategy: DensificationStrategy = field(default_factory=DensificationStrategy)
    initial_opacity: float = 0.1
    random_init_points: int = 100_000
    background_points: int = 0
    background_radius: float = 30.0
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    tile_size: int = 8
    seed: int = 0

    @classmethod
    def schedule(cls, iterations: int, *, densify_every: int, **overrides: object) -> FitConfig:
        """The standard schedule compressed to ``iterations``: raise the SH degree every 10 % of the run,
        and the strategy's (:meth:`DensificationStrategy.schedule`): densify from 10 % to 60 % every
        ``densify_every`` iterations, reset opacities every 30 %.  ``overrides`` name fields of the
        configuration or of its strategy (e.g. ``opacity_reset_every``, ``max_gaussians``)."""
        values, density = split_settings(overrides)
        values = {
            "iterations": iterations,
            "sh_increase_every": max(1, round(0.1 * iterations)),
            **values,
            "strategy": DensificationStrategy.schedule(iterations, densify_every=densify_every, **density),
        }
        return cls(**values)  # type: ignore[arg-type]

    def rescaled(self, iterations: int) -> FitConfig:
        """This configuration run for ``iterations``: every field counted in iterations
        (``sh_increase_every`` and the strategy's :attr:`~DensificationStrategy.SCHEDULE_FIELDS`) scales
        by the same ratio (at least 1); an event this run never reaches (e.g. an opacity reset after the
        last iteration, i.e. disabled) stays unreached; every other setting is kept."""
        ratio = iterations / self.iterations

        def scale(value: int) -> int:
            return iterations + 1 if value > self.iterations else max(1, round(value * ratio))

        names = DensificationStrategy.SCHEDULE_FIELDS
        strategy = dataclasses.replace(self.strategy, **{n: scale(getattr(self.strategy, n)) for n in names})
        return dataclasses.replace(
            self, iterations=iterations, sh_increase_every=scale(self.sh_increase_every), strategy=strategy
        )

    def learning_rates(self, extent: float) -> dict[str, float]:
        return {
            "means": self.lr_means * extent,
            "sh_dc": self.lr_sh_dc,
            "sh_rest": self.lr_sh_rest,
            "opacity_logits": self.lr_opacity,
            "log_scales": self.lr_scales,
            "quats": self.lr_quats,
        }

    def to_json(self) -> dict[str, object]:
        """The configuration as JSON values; the strategy's settings nested under ``"strategy"``."""
        data = dataclasses.asdict(self)
        data["background"] = list(self.background)
        return data

    @classmethod
    def from_json(cls, data: Mapping[str, object]) -> FitConfig:
        """The inverse of :meth:`to_json`; also reads the flat shape written before the strategy object
        (densification settings at the top level).  Missing keys take their defaults.

        Raises:
            UsageError: a key that names no setting, or a ``"strategy"`` that is not an object.
        """
        nested = data.get("strategy", {})
        if not isinstance(nested, Mapping):
            raise UsageError(f"fit configuration: 'strategy' must be an object, got {type(nested).__name__}")
        unknown = sorted(set(nested) - _STRATEGY_FIELDS)
        if unknown:
            raise UsageError(f"fit configuration: the strategy has no setting {unknown[0]!r}")
        values, density = split_settings({k: v for k, v in data.items() if k != "strategy"})
        if "background" in values:
            values["background"] = tuple(values["background"])  # type: ignore[call-overload]
        return cls(**values, strategy=DensificationStrategy(**{**nested, **density}))  # type: ignore[arg-type]


_STRATEGY_FIELDS = frozenset(f.name for f in dataclasses.fields(DensificationStrategy))
_CONFIG_FIELDS = frozenset(f.name for f in dataclasses.fields(FitConfig)) - {"strategy"}


def split_settings(settings: Mapping[str, object]) -> tuple[dict[str, object], dict[str, object]]:
    """``(configuration settings, strategy settings)`` of flat ``settings``, each named by its field.

    Raises:
        UsageError: a name that is a field of neither (one line naming it).
    """
    config: dict[str, object] = {}
    density: dict[str, object] = {}
    for name, value in settings.items():
        if name in _STRATEGY_FIELDS:
            density[name] = value
        elif name in _CONFIG_FIELDS:
            config[name] = value
        else:
            raise UsageError(f"fit configuration has no setting {name!r}")
    return config, density
