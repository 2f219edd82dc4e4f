"""Copies of the env's host buffers to the training device.

The env overwrites its buffers in every step, so the trainer keeps device copies. On the CPU a
copy is a plain `torch.tensor`. On CUDA a copy must come from page-locked memory to be
asynchronous (it then overlaps the env step, which runs without the GIL). Two ways:

- `host_register=True` (default): the env's own buffers are page-locked in place once
  (`cudaHostRegister`), and each upload reads them directly: no host copy at all. At the paper's
  size (16,384 slots x 2,186 floats) that is 143 MB of memcpy per env step saved.
- `host_register=False`, or where registration fails: each buffer is first copied into a pinned
  staging buffer of its own.

Either way an upload is safe to queue before the next env step: the trainer synchronises once
per env step (the action download), after every upload queued before it, so the env never
writes a buffer that the device is still reading.
"""

from __future__ import annotations

import warnings
import weakref

import numpy as np

from selfplaydrive._optional import requires_extra

with requires_extra("torch"):
    import torch
    from torch import Tensor


def _unregister(pointers: list[int]) -> None:
    if not pointers:
        return
    cudart = torch.cuda.cudart()
    for ptr in pointers:
        cudart.cudaHostUnregister(ptr)
    pointers.clear()


class Uploader:
    """Device copies of numpy arrays, keyed by the env buffer they come from.

    Args:
        device: The training device.
        host_register: On CUDA, page-lock the env's buffers in place rather than staging them.
    """

    def __init__(self, device: torch.device, host_register: bool = True) -> None:
        self.device = device
        self.cuda = device.type == "cuda"
        self.host_register = host_register and self.cuda
        self._host: dict[str, tuple[int, Tensor]] = {}  # key -> (data address, registered view)
        self._staging: dict[str, Tensor] = {}
        self._registered: list[int] = []
        self.failed: dict[str, str] = {}  # key -> why registration failed (staged instead)
        weakref.finalize(self, _unregister, self._registered)

    def __call__(self, array: np.ndarray, key: str) -> Tensor:
        """A device copy of `array` (a private one: the env overwrites its buffers)."""
        if not self.cuda:
            return torch.tensor(array, device=self.device)
        if self.host_register and key not in self.failed:
            host = self._registered_view(array, key)
            if host is not None:
                return host.to(self.device, non_blocking=True)
        return self._staged(array, key)

    def _registered_view(self, array: np.ndarray, key: str) -> Tensor | None:
        address = array.ctypes.data
        entry = self._host.get(key)
        if entry is not None and entry[0] == address and tuple(entry[1].shape) == array.shape:
            return entry[1]
        if not array.flags.c_contiguous or array.nbytes == 0:
            self.failed[key] = "not a contiguous, non-empty array"
            return None
        if address not in self._registered:  # two keys may read one buffer (env.masks)
            err = torch.cuda.cudart().cudaHostRegister(address, array.nbytes, 0)
            if int(err) != 0:
                self.failed[key] = f"cudaHostRegister returned {err}"
                warnings.warn(
                    f"env buffer {key!r} ({array.nbytes} bytes) could not be page-locked in place "
                    f"({self.failed[key]}); its uploads go through a pinned staging copy",
                    RuntimeWarning,
                    stacklevel=3,
                )
                return None
            self._registered.append(address)
        with warnings.catch_warnings():  # the env's views are read-only; torch only reads them
            warnings.simplefilter("ignore", UserWarning)
            view = torch.from_numpy(array)
        self._host[key] = (address, view)
        return view

    def _staged(self, array: np.ndarray, key: str) -> Tensor:
        buf = self._staging.get(key)
        if buf is None or tuple(buf.shape) != array.shape:
            buf = torch.from_numpy(np.empty_like(array)).pin_memory()
            self._staging[key] = buf
        np.copyto(buf.numpy(), array)
        return buf.to(self.device, non_blocking=True)
