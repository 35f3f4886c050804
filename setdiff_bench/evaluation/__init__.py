"""Stage 2, packets → scores: enhancer runs (:mod:`.run`) and their folders (:mod:`.paths`), per-target
scoring (:mod:`.scoring`), evaluation profiles (:mod:`.profiles`, :mod:`.profile_scoring`,
:mod:`.euvs_compat`) and the closed-loop session (:mod:`.stream`)."""
