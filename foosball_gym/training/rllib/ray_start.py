"""Starting Ray, or joining a cluster, for a run of the RLlib backend."""

from __future__ import annotations

INSTALL = 'pip install -e ".[distributed]"'
# Ray itself retries an unreachable head for many minutes before it gives up.
CONNECT_TIMEOUT_S = 10.0


def require_ray() -> None:
    """Raise ImportError naming the ``distributed`` extra where Ray RLlib or PyTorch is missing."""
    try:
        import pettingzoo  # noqa: F401
        import ray.rllib  # noqa: F401
        import torch  # noqa: F401
    except ImportError as err:
        raise ImportError(
            f"the rllib backend needs Ray RLlib, PettingZoo and PyTorch ({err.name} is "
            f"missing); install them with: {INSTALL} in a checkout, or "
            'pip install -e ".[distributed]"'
        ) from err


def check_reachable(address: str) -> None:
    """Raise ConnectionError where ``HOST:PORT`` takes no connection within the timeout."""
    import socket

    if address == "auto" or address.startswith("ray://"):
        return
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        raise ValueError(f"--address must be HOST:PORT or auto, got {address!r}")
    try:
        with socket.create_connection((host, int(port)), timeout=CONNECT_TIMEOUT_S):
            pass
    except OSError as err:
        raise ConnectionError(
            f"no Ray head answers at {address} within {CONNECT_TIMEOUT_S:.0f} s ({err})"
        ) from None


def start_ray(address: str | None, num_workers: int) -> bool:
    """Connect to (or start) Ray; True where this call started it and must shut it down."""
    import ray

    if ray.is_initialized():
        return False
    if address:
        check_reachable(address)
        ray.init(address=address, include_dashboard=False, log_to_driver=False)
    else:
        # One CPU per env runner, on top of the driver (which runs the learner).
        ray.init(
            address="local",
            num_cpus=max(num_workers, 1),
            include_dashboard=False,
            log_to_driver=False,
        )
    return True
