"""What the app reads back is data, never code: the allowlists for a checkpoint and for a packed env state.

A pickle names functions that unpickling calls, so a crafted `.pt` given as `checkpoint=`, `init_from=` or
`resume=` would run whatever it names. Two readers close that door:
- a checkpoint file is read by `torch.load(weights_only=True)`, which builds tensors, numbers, strings and plain
  containers only; numpy arrays and scalars (the normalization statistics, numpy's RNG state) are added through
  torch's public `add_safe_globals` as exactly their reconstruct functions and numeric dtypes (`TORCH_ALLOWED`);
- the env-side state inside it is one pickled `bytes` value (env_state.pack: fast between TorchRL's worker
  processes), read by `loads`: an unpickler whose `find_class` knows a short allowlist (`UNPICKLE_ALLOWED`:
  numpy arrays and scalars, tensors, OrderedDict; RNG states are dicts) and refuses any other name before
  anything runs. A tensor's storage, which torch pickles as `torch.save` bytes, is read by torch's own
  weights_only loader, not by `torch.storage._load_from_bytes` (which would trust it).
The functions are taken from how numpy and torch pickle their own objects (`__reduce_ex__`), so the names match
what this numpy and torch write, with numpy 1's `numpy.core` spelled too.
"""

from __future__ import annotations

import collections
import functools
import io
import pickle
import re
from typing import Optional

import numpy as np
import torch


def _rebuilder(obj, protocol: int = 2):
    """The function `obj` is rebuilt with when pickled."""
    return obj.__reduce_ex__(protocol)[0]


_NUMPY_RECONSTRUCT = _rebuilder(np.zeros(1))  # ndarray: _reconstruct(ndarray, shape, dtype) + its state
_NUMPY_FROMBUFFER = _rebuilder(np.zeros(1), 5)  # ndarray at protocol 5
_NUMPY_SCALAR = _rebuilder(np.float64(0))  # numpy scalar: scalar(dtype, bytes)
_NUMERIC_DTYPES = [type(np.dtype(code)) for code in "?" + np.typecodes["AllInteger"] + np.typecodes["AllFloat"]]


def _names(function) -> list:
    """(module, name) as pickle writes `function`, and as numpy 1 wrote it (`numpy.core`)."""
    names = [(function.__module__, function.__qualname__)]
    if function.__module__.startswith("numpy._core"):
        names.append((function.__module__.replace("numpy._core", "numpy.core"), function.__qualname__))
    return names


# torch.load(weights_only=True) builds these too (a dtype is rebuilt as its class, hence the dtype classes).
TORCH_ALLOWED = [np.ndarray, np.dtype, *dict.fromkeys(_NUMERIC_DTYPES),
                 *((f, ".".join(name)) for f in (_NUMPY_RECONSTRUCT, _NUMPY_SCALAR) for name in _names(f))]


class Refused(pickle.UnpicklingError):
    """A pickle that names something outside the allowlist; `what` is its `module.name`."""

    def __init__(self, what: str):
        super().__init__(f"{what} is not data this app reads back")
        self.what = what


def _tensor_storage(data: bytes):
    """A storage as torch pickles it (`torch.save` bytes), read by torch's safe loader."""
    return torch.load(io.BytesIO(data), weights_only=True)


def _latin1_bytes(text: str, encoding: str) -> bytes:
    """`bytes` as pickle protocol 2 writes them: `_codecs.encode(text, "latin1")`, that codec only."""
    if encoding != "latin1":
        raise Refused(f"_codecs.encode with {encoding!r}")
    return text.encode("latin1")


UNPICKLE_ALLOWED = {name: function for function in (_NUMPY_RECONSTRUCT, _NUMPY_FROMBUFFER, _NUMPY_SCALAR, np.ndarray,
                                                    np.dtype, collections.OrderedDict, _rebuilder(torch.zeros(1)))
                    for name in _names(function)}
UNPICKLE_ALLOWED.update({("torch.storage", "_load_from_bytes"): _tensor_storage, ("_codecs", "encode"): _latin1_bytes})


class _Restricted(pickle.Unpickler):
    def find_class(self, module: str, name: str):
        try:
            found = UNPICKLE_ALLOWED[(module, name)]
        except KeyError:
            raise Refused(f"{module}.{name}") from None
        # A function as a fresh partial: a pickle's BUILD may set attributes on what it gets, never on the function.
        return found if isinstance(found, type) else functools.partial(found)


def loads(data: bytes):
    """`pickle.loads` of data only (module doc): a `Refused` error for any other name, before anything runs."""
    return _Restricted(io.BytesIO(data)).load()


def load_torch(path):
    """`torch.load(path, weights_only=True)` on the CPU, numpy arrays and scalars allowed."""
    torch.serialization.add_safe_globals(TORCH_ALLOWED)  # idempotent; arrays are data for any weights_only load
    return torch.load(path, map_location="cpu", weights_only=True)


def refused_name(error: BaseException) -> Optional[str]:
    """What a refused pickle asked for (`module.name`, or the class it would build), None for an error that
    is not a refusal (a truncated or foreign file: a zip error, an opcode torch does not read)."""
    if isinstance(error, Refused):
        return error.what
    text = str(error)
    named = (re.search(r"GLOBAL (\S+) (?:was not an allowed global|whose module)", text)
             or re.search(r"but got <class '([^']+)'>", text))
    return named.group(1) if named else None
