"""Stage 2, packets → scores: enhancer runs (:mod:`.run`) and their folders (:mod:`.paths`), per-target
scoring (:mod:`.scoring`), applying evaluation profiles (:mod:`.profile_scoring`, :mod:`.euvs_compat`; the
profiles themselves are protocol data, :mod:`setdiff_bench.protocols.profiles`) and the closed-loop session (:mod:`.stream`)."""
