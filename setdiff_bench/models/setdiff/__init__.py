"""SetDiff and, on the same code, its DiFix3D-style baseline (``method = "difix"`` in a model config: one
reference and one target per set, RGB only, no geometry, no CFG).

The folder as a tree, leaves first:

* ``files`` — every file name of a checkpoint, a training run, an autoencoder and a shipped model;
* ``methods`` — the methods this package trains and runs (``setdiff``, ``difix``), declared once;
* ``packaged`` — the lookup table of the models shipped under ``weights/``;
* ``autoencoder`` — finding and reading a trained tiny autoencoder (its training: ``autoencoder_train``,
  with its settings in ``autoencoder_settings``);
* ``presets`` — the architectures as data; ``config`` — the ``ModelConfig`` / ``TrainConfig`` dataclasses;
  ``config_io`` — config TOML files;
* ``networks``, ``geometry_encoder``, ``set_mixer``, ``vae_codec``, ``inputs``, ``model`` — the model;
* ``checkpoint``, ``averaging``, ``export`` — saving, loading, averaging and exporting weights;
* ``inference``, ``memory``, ``domain`` — enhancing a packet, its memory bound, its training-data check;
* ``losses``, ``sample_stream``, ``validation``, ``train_log``, ``manifest``, ``train`` — training: its loss,
  the resumable stream of samples, validation, the JSON-lines logs, provenance and the loop.

``tests/core/test_import_graph.py`` keeps it a tree: no module here imports one that imports it back.
"""
