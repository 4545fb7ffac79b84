"""A training run's directory, the same for both backends: its file names (:mod:`.files`),
its evaluation curve (:mod:`.curve`) and best model (:mod:`.best`), the record of its physics
(:mod:`.physics`), its model files written without pickle (:mod:`.storage`, :mod:`.tensors`)
and the conversion of runs from before (:mod:`.migrate`).

Imports neither backend; :mod:`.files`, :mod:`.curve` and :mod:`.physics` need no PyTorch.
"""
