"""``--device``: a torch device checked before any work, never silently ignored.

An unknown string (``tpu9``) or CUDA asked for on a machine without it is refused with
one line, instead of a torch traceback half-way through a run or an embedder that quietly
runs on the CPU. torch is imported only when a device is given.
"""

from __future__ import annotations

from physinfer.errors import UserInputError


def check_device(device: str | None, option: str = "--device") -> str | None:
    """``device`` if this machine has it; ``None`` (the default device) stays ``None``.

    Args:
        device: A torch device string: ``cpu``, ``cuda``, ``cuda:N``, ``mps``.
        option: The CLI option that gave it, for the message.

    Returns:
        The device as torch spells it (``"cuda:0"``), or ``None``.

    Raises:
        UserInputError: not a torch device, or one this machine does not have.
    """
    if device is None:
        return None
    import torch

    try:
        parsed = torch.device(str(device))
    except (RuntimeError, ValueError):
        raise UserInputError(f"{option} {device!r} is not a torch device; use cpu, cuda or cuda:N") from None
    if parsed.type == "cuda":
        count = torch.cuda.device_count() if torch.cuda.is_available() else 0
        if count == 0:
            raise UserInputError(f"{option} {device}: this machine has no CUDA GPU; use {option} cpu")
        if parsed.index is not None and parsed.index >= count:
            raise UserInputError(f"{option} {device}: this machine has {count} CUDA GPU(s), cuda:0 to cuda:{count - 1}")
    elif parsed.type == "mps" and not torch.backends.mps.is_available():
        raise UserInputError(f"{option} {device}: MPS is not available here; use {option} cpu")
    elif parsed.type not in ("cpu", "cuda", "mps"):
        raise UserInputError(f"{option} {device}: physinfer runs on cpu, cuda or mps")
    return str(parsed)
