"""Evaluation protocols (installed as ``setdiff_bench.protocols``): TOML definitions, split lists, reported numbers.

A protocol file (``protocols/<name>.toml``, format ``setdiff-protocol/1``) declares, for one dataset:

* ``[loader]`` — keyword options for :func:`setdiff_bench.loaders.load_scenes`;
* ``[split]`` — the scene-level train/test split for enhancer training (:mod:`.scene_split`);
* ``[images]`` — working resolution ``[height, width]`` (or ``"native"``: the scene's own), how
  captures are brought to it (``resize = "crop"``: centre-crop to the aspect ratio, then resize;
  ``"stretch"``: resize only) and where evaluation masks come from (``masks``: ``"dataset"`` =
  ``Frame.mask_path``, 255 = keep; ``"foreground"`` = ``metadata["foreground_mask_path"]`` inverted;
  ``"none"`` = every pixel evaluated);
* ``[references]`` — Eq. 2's ``alpha`` and ``beta``, how a candidate's scores over the packet's
  targets aggregate (``mean``), and the reference count N per packet for ``train`` and ``test`` scenes;
* ``[packets]`` — views stored per packet (N + M) for training and test scenes, and the set-size
  range the training loader draws from;
* ``[render]`` — ``cmap_clip``: Gaussian centres are clipped to a box of half-width
  ``cmap_clip × d_max`` around the mean camera centre of the scene before the C-map is composited
  (the paper's "clipped by scene scale"; ``d_max`` = largest pairwise camera distance in the scene;
  0 = no clipping);
* ``[evaluation]`` — ``profiles``: the evaluation profiles that apply to this protocol's runs
  (:data:`setdiff_bench.protocols.profiles.PROFILES`; default ``["paper"]``, the first is the default);
* ``[leaderboard]`` — the table shape of the dataset's leaderboard (:class:`Layout`), read from the
  dataset's default protocol (``protocols/<dataset>.toml``) by :mod:`setdiff_bench.reporting.leaderboard`:
  ``title`` (caption), ``blocks`` (column blocks in order: ``{ group = "<group name>", label = "..." }``
  or ``{ pooled = true, label = "All" }`` for every group pooled; absent = one block per group found),
  ``metrics`` (image metrics per block, default ``["psnr", "ssim", "lpips"]``), ``sequence_metrics``
  (per-sequence metrics shown in the pooled block) and ``reported_tables`` (``table`` ids of
  ``protocols/reported/*.csv`` of this dataset that ``--with-reported`` mixes in); optional;
* ``[[groups]]`` — evaluation groups: a name, a rule (:mod:`.rules`) with its parameters, the
  ``fit_key`` naming the 3DGS fit (``<fits>/<scene>/<fit_key>.ply``) and an optional ``scenes``
  filter on ``Scene.metadata`` (EUVS ``level``).

Usage::

    from setdiff_bench.protocols import load_protocol
    protocol = load_protocol("euvs")                 # packaged file, or a path to a TOML
    split = protocol.split.assign(scene_names)       # {scene: "train" | "test"}
    frames = protocol.groups[0].select(scene)        # GroupFrames(fit, targets)

Every problem in a file is a :class:`~setdiff_bench.errors.ProtocolError` naming the file and key.

Modules: :mod:`.model` (the validated protocol and its parts), :mod:`.parser` (the packaged files, reading and
validating one), :mod:`.schema` (typed TOML tables), :mod:`.rules` (group rules), :mod:`.scene_split`.
"""

from .model import (
    POOLED,
    SPLITS,
    Block,
    GroupSpec,
    ImageSpec,
    Layout,
    MaskSource,
    PacketSpec,
    Protocol,
    ReferenceSpec,
)
from .parser import (
    FORMAT,
    PROTOCOL_NAMES,
    list_protocols,
    load_protocol,
    parse_protocol,
    protocol_dir,
    protocol_path,
)
from .rules import GroupFrames
from .scene_split import SceneSplit

__all__ = [
    "FORMAT",
    "POOLED",
    "PROTOCOL_NAMES",
    "SPLITS",
    "Block",
    "GroupFrames",
    "GroupSpec",
    "ImageSpec",
    "Layout",
    "MaskSource",
    "PacketSpec",
    "Protocol",
    "ReferenceSpec",
    "SceneSplit",
    "list_protocols",
    "load_protocol",
    "parse_protocol",
    "protocol_dir",
    "protocol_path",
]
