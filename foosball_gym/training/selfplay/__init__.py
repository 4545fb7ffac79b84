"""Self-play, for either backend: when the opponent is replaced (:mod:`.rule`), the record of
the snapshots (:mod:`.history`), the gate a replacement may have to pass (:mod:`.gate`),
matches between two policies (:mod:`.matches`) and the league that rates a run's generations
(:mod:`.league`). Stable-Baselines3's side plays its opponents in the vectorised envs
(:mod:`.opponents`) and replaces them from a callback (:mod:`.callback`).

Imports neither backend's trainer; :mod:`.rule`, :mod:`.history`, :mod:`.matches` and
:mod:`.league` need no PyTorch.
"""
