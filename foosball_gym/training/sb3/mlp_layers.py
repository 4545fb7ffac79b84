"""The linear layers of an SB3 MLP, by name, for the learners that compute it outside PyTorch."""

from __future__ import annotations

import torch as th


def mlp_layers(sequential: th.nn.Module, prefix: str) -> list[tuple[str, str, str]]:
    """(weight name, bias name, activation) for each linear layer of an SB3 MLP."""
    modules = list(sequential.named_children())
    layers = []
    for i, (name, module) in enumerate(modules):
        if isinstance(module, th.nn.Linear):
            after = modules[i + 1][1] if i + 1 < len(modules) else None
            if isinstance(after, th.nn.Tanh):
                act = "tanh"
            elif isinstance(after, th.nn.ReLU):
                act = "relu"
            elif after is None:
                act = "none"
            else:
                raise ValueError(
                    f"the learners know tanh and ReLU layers, not {type(after).__name__}"
                )
            layers.append((f"{prefix}{name}.weight", f"{prefix}{name}.bias", act))
        elif not isinstance(module, th.nn.Tanh | th.nn.ReLU):
            raise ValueError(f"the learners know linear layers, not {type(module).__name__}")
    return layers
