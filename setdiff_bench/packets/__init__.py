"""Stage 1, dataset → packets: planning (:mod:`.plan`), rendering and writing (:mod:`.prepare`),
the on-disk store (:mod:`.store`) and its index (:mod:`.index`), and ``--shard`` splitting (:mod:`.shards`)."""
