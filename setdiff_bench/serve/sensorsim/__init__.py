"""``setdiff-bench serve --protocol sensorsim``: AlpaSim's renderer protocol (NuRec-compatible ``SensorsimService``),
as a 3DGS renderer of fitted scenes or as an enhancing proxy in front of any sensorsim renderer.

``sensorsim.proto`` / ``common.proto`` define the wire format (AlpaSim's names and field numbers);
``*_pb2*.py`` are generated from them (command in ``common.proto``).  :mod:`.lens` converts requested cameras
and renders through their lenses, :mod:`.scenes` reads the folder of fitted scenes, :mod:`.imaging` encodes and
decodes PNG / JPEG, :mod:`.enhancing` holds the per-scene enhancement sessions, :mod:`.service` answers the
RPCs of both roles, :mod:`.server` binds and starts them, and :mod:`.settings` says how they run.
"""
