"""Stage 1, dataset → packets, in the order the data flows:

* options of a call: :mod:`.prepare_settings`; the call itself (scenes, units, resume, index): :mod:`.prepare`;
* fits, found or trained: :mod:`.fits`;
* planning (:mod:`.plan`, the protocol's groups): views at the working resolution (:mod:`.working_view`),
  packing targets and choosing references (:mod:`.packing`), jobs and their recipe hash (:mod:`.jobs`),
  novel trajectories (:mod:`.trajectory`, :mod:`.plan_trajectories`) and training pairs (:mod:`.recipes`,
  :mod:`.plan_pairs`; the cycle recipe's renders at shifted cameras: :mod:`.cycle`);
* rendering and writing one packet (:mod:`.worker`), many of them (:mod:`.execute`), its files
  (:mod:`.writer`);
* the on-disk store (:mod:`.store`) and its index (:mod:`.index`), training samples from it
  (:mod:`.training_dataset`), and ``--shard`` splitting (:mod:`.shards`).
"""
