"""How ``setdiff-bench serve --protocol sensorsim`` runs (no grpc or torch import: ``serve --help`` stays fast)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from setdiff_bench.serve.settings import ServeSettings

Role = Literal["renderer", "proxy"]
ROLES: tuple[str, ...] = ("renderer", "proxy")
#: Largest message either way (bytes): AlpaSim's runtime sends and receives at most 64 MiB.
MAX_MESSAGE_BYTES = 64 * 1024 * 1024


@dataclass(frozen=True)
class SensorsimSettings:
    """The sensorsim service: its role, scenes and upstream, plus the enhancer server's settings.

    Attributes:
        serve: host, port, TLS, token, workers, queue, sessions (one per scene and frame size), idle expiry and
            the memory bound of a session (:class:`~setdiff_bench.serve.settings.ServeSettings`).
        role: ``renderer`` (render the scenes' 3DGS; enhance in place when a checkpoint is given) or ``proxy``
            (forward every call to ``upstream`` and enhance the images it returns).
        scenes: folder of fitted scenes (:mod:`setdiff_bench.serve.sensorsim.scenes`): what the renderer
            renders, and where the proxy finds each scene's recorded frames and PLY (for C-maps).
        upstream: ``host:port`` of the renderer the proxy forwards to (plaintext gRPC, as AlpaSim's own
            channels; keep it on a trusted network).
        upstream_timeout: seconds the proxy waits for the upstream renderer per call; past it every camera of
            the call is answered ``success = false``.
        upstream_png: ask the upstream renderer for lossless PNG whatever the client asked (the enhancer then
            never sees JPEG artefacts); ``False``: forward the client's format and quality.
        max_loaded_scenes: scenes (Gaussians and frame lists) kept loaded at once, least recently used dropped.
    """

    serve: ServeSettings = field(default_factory=ServeSettings)
    role: Role = "renderer"
    scenes: Path | None = None
    upstream: str | None = None
    upstream_timeout: float = 30.0
    upstream_png: bool = True
    max_loaded_scenes: int = 8
