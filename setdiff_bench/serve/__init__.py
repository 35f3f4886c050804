"""``setdiff-bench serve``: the stream API (:mod:`setdiff_bench.evaluation.stream`) as a gRPC service.

``enhancer.proto`` defines the wire format; ``enhancer_pb2*.py`` are generated from it (command in
the .proto).  :mod:`.wire` converts messages to tensors and cameras, :mod:`.server` serves,
:mod:`.client` is the small Python client.
"""
