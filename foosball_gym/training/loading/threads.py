"""How many threads PyTorch gets where a trained policy plays."""

from __future__ import annotations

import os

# Set where the user asks for a number of threads of their own.
THREAD_VARIABLES = ("OMP_NUM_THREADS", "MKL_NUM_THREADS")


def use_one_torch_thread() -> int:
    """Give PyTorch one thread, unless ``OMP_NUM_THREADS`` (or ``MKL_NUM_THREADS``) asks for
    another number; the number it then has.

    A policy here is a small network called on one observation at a time, between physics
    steps on the same cores: a second thread only waits for the first, and on a machine whose
    cores are busy it waits long (``foosball eval``, the labs: see docs/training.md). Training
    has its own setting, ``torch_threads``.
    """
    import torch

    if not any(os.environ.get(name) for name in THREAD_VARIABLES):
        torch.set_num_threads(1)
    return torch.get_num_threads()
