"""``setdiff-bench serve``: the stream API (:mod:`setdiff_bench.evaluation.stream`) as a gRPC service.

``enhancer.proto`` defines the wire format; ``enhancer_pb2*.py`` are generated from it (command in
the .proto).  :mod:`.wire` converts messages to tensors and cameras; :mod:`.auth` checks bearer tokens,
:mod:`.rpc_errors` answers refusals and failures, :mod:`.sessions` holds a session's record and the model
lock, :mod:`.servicer` handles the RPCs, and :mod:`.server` binds, starts and stops (its docstring: the
behaviour under load); :mod:`.client` is the small Python client.
"""
