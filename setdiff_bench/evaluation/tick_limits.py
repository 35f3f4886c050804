"""The sizes of one closed-loop tick, shared by the stream session and the service's settings (a light
module: ``serve --help`` reads these without loading torch)."""

from __future__ import annotations

#: Most cameras one tick may carry (a rig of this many views is one set).
MAX_CAMERAS_PER_TICK = 16

#: References per tick when neither the session nor the enhancer caps them (a model config's
#: ``max_references = null`` means "every reference of the packet"; a session's recorded drive may
#: hold hundreds, so a tick takes the paper's inference packet: 8 references beside up to 8 targets).
DEFAULT_REFERENCES_PER_TICK = 8
