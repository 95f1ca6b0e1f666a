"""The torch device a learner runs on, checked: a device this machine lacks is the user's error.

Training puts the agent, its batched inference and the PPO update on this device; the envs,
their observations and actions stay numpy on the CPU (Drake runs there).
"""

from __future__ import annotations

import torch

from corn_drake.errors import InputError

DEVICE_TYPES = ("cpu", "cuda")


def training_device(name: str, label: str = "device") -> torch.device:
    """`name` ("cpu", "cuda", "cuda:N") as a torch.device, or an InputError naming `label` (the
    flag or config field it came from) when it is malformed or this machine cannot run it."""
    try:
        device = torch.device(name)
    except (RuntimeError, TypeError):
        device = None
    if device is None or device.type not in DEVICE_TYPES or (device.type == "cpu" and device.index):
        raise InputError(f"{label} {name!r}: expected cpu, cuda or cuda:N")
    if device.type == "cuda":
        if not torch.cuda.is_available():
            why = (f"this torch ({torch.__version__}) is built without CUDA"
                   if torch.version.cuda is None else "no CUDA GPU is visible")
            raise InputError(f"{label} {name}: CUDA is not available on this machine ({why}); "
                             "use cpu")
        count = torch.cuda.device_count()
        if device.index is not None and device.index >= count:
            raise InputError(f"{label} {name}: this machine has {count} CUDA device(s)")
    return device
