"""The file names of every folder the SetDiff / DiFix code writes and reads, declared once.

* a **checkpoint** (:mod:`~setdiff_bench.models.setdiff.checkpoint`; a shipped enhancer is one):
  ``config.json`` + ``model.safetensors``, and while training ``optimizer.pt`` + ``trainer.json``;
* a **training run** (:mod:`~setdiff_bench.models.setdiff.train`): ``checkpoints/step-<step>/`` checkpoints, the
  newest named in ``latest``, the provenance ``manifest.json`` (:mod:`~setdiff_bench.models.setdiff.manifest`)
  and the ``train_log.jsonl`` / ``validation.jsonl`` / ``samples.jsonl`` logs;
* an **autoencoder** (:mod:`~setdiff_bench.models.setdiff.autoencoder`): ``config.json`` +
  ``weights.safetensors`` + ``manifest.json``, and ``training_state.pt`` until its training ends;
* the **shipped models** (:mod:`~setdiff_bench.models.setdiff.packaged`): one folder each under the package's
  ``weights/``.
"""

from __future__ import annotations

#: A checkpoint's or an autoencoder's config (a JSON object).
CONFIG_FILE = "config.json"
#: A checkpoint's weights (every parameter of the enhancer).
WEIGHTS_FILE = "model.safetensors"
#: An autoencoder's weights (every VAE parameter, float32).
AUTOENCODER_WEIGHTS_FILE = "weights.safetensors"
#: Provenance of a training run, a shipped model or an autoencoder.
MANIFEST_FILE = "manifest.json"
OPTIMIZER_FILE = "optimizer.pt"
TRAINER_FILE = "trainer.json"
#: In a training run's folder: the name of its newest checkpoint folder.
LATEST_FILE = "latest"
CHECKPOINTS_DIR = "checkpoints"
LOG_FILE = "train_log.jsonl"
VALIDATION_FILE = "validation.jsonl"
SAMPLES_FILE = "samples.jsonl"
#: An autoencoder's resume point (removed once its files are written).
AUTOENCODER_STATE_FILE = "training_state.pt"
#: Where the shipped models lie, inside this package.
PACKAGED_FOLDER = "weights"
#: What a trained autoencoder folder holds.
AUTOENCODER_FILES = (CONFIG_FILE, AUTOENCODER_WEIGHTS_FILE, MANIFEST_FILE)
