"""3D Gaussian Splatting: the model, its standard PLY file, rendering (RGB + C-map + depth) and fitting."""

from setdiff_bench.gaussians.model import GaussianModel

__all__ = ["GaussianModel"]
