"""The embedded benchmark end to end: synthetic test scenes → 3DGS fits → packets → ``identity``,
``reproject``, ``difix``, ``setdiff`` → leaderboard, plots, grids.

By default the demo evaluates the models shipped in the package (``tiny_setdiff``, ``tiny_difix``:
:mod:`setdiff_bench.models.setdiff.packaged`), trained with the toolkit's own commands on synthetic
scenes whose generator seeds are disjoint from the demo's test scenes (checked before any work).  It
generates and fits only the preset's **test** scenes (the synthetic protocol's scene split over the
preset's scene list), declares them the test split of the packet store (``prepare --test-scene``),
runs the four methods and writes the leaderboard.  ``--train`` keeps the whole path instead: every
scene, SetDiff and DiFix trained on the training scenes, then the same evaluation (and, on request,
the two ablations, which need training).

Every stage is an ordinary ``setdiff-bench`` command run in its own process
(:mod:`setdiff_bench.pipeline.stages`); the demo records each command and its wall time in
``<out>/README.md`` and ``<out>/demo.json``.  Bulky intermediate data (scenes, packets,
checkpoints, runs) goes to ``<out>/work``; tables, plots and the report sit in ``<out>``, by default
the scratch folder ``runs/demo`` (git-ignored).  The project's published results are replaced only
on purpose, by ``setdiff-bench publish`` (:mod:`setdiff_bench.pipeline.publish`).  Every stage resumes, so an
interrupted demo continues where it stopped; a stage finished by an earlier run keeps its original
time in the report, marked resumed (``<work>/stages.json``).

``demo.json`` is written last (and removed when a run starts), so its presence means the outputs
beside it are complete and from one run; it records the provenance (git revision, command, seed,
torch thread count, package versions) and the SHA-256 of every output.

Presets (``--preset``):

* ``tiny``: tiny scenes (80×48) — a smoke test (CI runs it with and without ``--train``).  Its
  numbers mean nothing.
* ``default``: the ``default`` synthetic preset's 2 test scenes at 256×144 with the shipped models
  (about 5 minutes on 2 CPU cores, measured in README.md); with ``--train``, all 6 scenes and short CPU
  training.
* ``full``: the ``large`` synthetic preset (8 scenes at 512×288); meant for ``--train`` on a GPU.

``--benchmark sparse`` runs the same stages on the sparse-view benchmark
(:data:`setdiff_bench.pipeline.presets.DEMO_BENCHMARKS`): the ``sparse*`` synthetic presets' walks in
DL3DV's layout, prepared with the packaged ``dl3dv_sparse_synthetic`` protocol (its listed test scenes
``sparse_0000_00`` and ``sparse_0000_01``, so seed 0), the shipped ``tiny_setdiff_sparse`` and
``tiny_difix_sparse``, and the leaderboard in Table 4's layout beside the paper's reported DL3DV rows,
with the metrics-against-view-count plot.

Modules, in the order a demo uses them: :mod:`.demo_layout` (its folders and files), :mod:`.demo_scenes`
(the test scenes and the shipped models' unseen check), :mod:`.demo_stages` (every stage's command, as
data), this module (:func:`run_demo`, which runs them), :mod:`.demo_summary` (``demo.json``) and
:mod:`.demo_report` (``README.md``).

The package's modules are private (``_demo`` runs it, its stages declared in ``_stages``, its folders in
``_layout``, test scenes in ``_scenes``, ``demo.json`` in ``_summary``, its README in ``_report``).
"""

from __future__ import annotations

from setdiff_bench.pipeline.demo._demo import run_demo
from setdiff_bench.pipeline.demo._layout import REPORT_FILE, SUMMARY_FILE, DemoPaths
from setdiff_bench.pipeline.demo._report import report_markdown, threads_line
from setdiff_bench.pipeline.demo._scenes import SHIPPED_MODELS, check_unseen, evaluation_scene_indices
from setdiff_bench.pipeline.demo._stages import METHODS

__all__ = [
    "METHODS",
    "REPORT_FILE",
    "SHIPPED_MODELS",
    "SUMMARY_FILE",
    "DemoPaths",
    "check_unseen",
    "evaluation_scene_indices",
    "report_markdown",
    "run_demo",
    "threads_line",
]
