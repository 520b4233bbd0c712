"""The closed loop: the ordered stages of one period (:mod:`.loop`), the offline loop that runs them (:mod:`.sim`),
the trajectory table every source builds (:mod:`.trajectory`) and the metrics of a run (:mod:`.metrics`).
"""
