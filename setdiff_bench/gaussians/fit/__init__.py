"""3D Gaussian Splatting optimisation (Kerbl et al. 2023), the graphdeco-inria training loop on our renderer.

Per iteration: pick the next view of a seeded per-epoch permutation, render it (torch backend on the
CPU, gsplat on CUDA), loss ``(1 − λ)·L1 + λ·(1 − SSIM)`` with λ = 0.2 and the 3DGS SSIM (zero-padded
"same" border, :func:`setdiff_bench.metrics.ssim.ssim`), Adam step with the standard per-parameter
learning rates (position rate × scene extent, decayed exponentially), then adaptive density control
(:mod:`setdiff_bench.gaussians.densify`) and opacity resets on the schedule.  The active SH degree grows by one every
``sh_increase_every`` iterations.  Pixels outside a view's mask (EUVS dynamic masks: 0 = moving
object) take the ground-truth value in the prediction, so they add neither loss nor gradient.

Initialisation (:func:`fit_gaussians`): the given points — for :func:`fit_scene` the scene's sparse
points (COLMAP ``points3D``) when present, else points triangulated from the known poses
(:mod:`setdiff_bench.gaussians.fit._triangulate`) — else :func:`random_init_count` uniform points in the box of the camera centres grown by the scene radius on
every side (colour grey), each as an isotropic Gaussian (nearest-neighbour scale, opacity 0.1).

Checkpoints (``checkpoint_dir``): parameters, Adam moments, density statistics and the random state in
``fit_state.safetensors``; iteration, schedule position, config and view names in ``fit_state.json``
(written last, with the tensor file's SHA-256, so a torn pair is detected).  Resuming restores all
of it, so an interrupted fit ends with exactly the model an uninterrupted one would.  A checkpoint
written before the densification settings moved into ``FitConfig.strategy`` (flat keys) still resumes.

The fit by concept, each a private module: ``_config`` (settings and schedule), ``_init`` (initial Gaussians),
``_trainer`` (the optimisation state and step), ``_checkpoint`` (checkpoint I/O), ``_data`` (a scene's fit
views), ``_triangulate`` (initial points from the views' poses) and ``_fit``, which runs the loop (:func:`fit_gaussians`) and fits a scene folder to a PLY
(:func:`fit_scene`).

The package's modules are private; this face exports what other code uses.
"""

from __future__ import annotations

from setdiff_bench.gaussians.fit._checkpoint import STATE_JSON, load_checkpoint, save_checkpoint, saved_config
from setdiff_bench.gaussians.fit._config import FitConfig
from setdiff_bench.gaussians.fit._data import (
    FitView,
    load_fit_scene,
    load_fit_views,
    parse_frame_list,
    select_fit_frames,
)
from setdiff_bench.gaussians.fit._fit import FitResult, fit_gaussians, fit_scene, fit_views_to_ply
from setdiff_bench.gaussians.fit._init import initial_model, scene_extent
from setdiff_bench.gaussians.fit._trainer import Trainer, photometric_loss
from setdiff_bench.gaussians.fit._triangulate import INIT_MODES, InitMode, initial_points, triangulate_views

__all__ = [
    "INIT_MODES",
    "STATE_JSON",
    "FitConfig",
    "FitResult",
    "FitView",
    "InitMode",
    "Trainer",
    "fit_gaussians",
    "fit_scene",
    "fit_views_to_ply",
    "initial_model",
    "initial_points",
    "load_checkpoint",
    "load_fit_scene",
    "load_fit_views",
    "parse_frame_list",
    "photometric_loss",
    "save_checkpoint",
    "saved_config",
    "scene_extent",
    "select_fit_frames",
    "triangulate_views",
]
