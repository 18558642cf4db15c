"""A memo that changes no value: a pure function of large inputs, called with the same
inputs by several units of one scene on one worker, computes once.

`last_call(key, size)` keeps the last `size` calls' results under `key(*args)`. It decides
no value, yet, like every line of a module, a decorator added or removed changes the code
key of what imports it (`bench.codehash`): the hash errs toward computing again.
"""

from __future__ import annotations

import functools
import hashlib
from collections import OrderedDict
from collections.abc import Callable

import numpy as np


def last_call(key: Callable[..., tuple], size: int = 1, hold: bool = True):
    """Decorate a pure function: a call whose `key(*args)` equals one of the last `size`
    distinct calls' returns that call's result. With `hold`, its arguments are held with it,
    so that an `id` in a key cannot be reused by another object while it is remembered; a
    key of digests alone needs no `hold`."""

    def wrap(fn):
        last: OrderedDict = OrderedDict()

        @functools.wraps(fn)
        def call(*args):
            k = key(*args)
            if k in last:
                last.move_to_end(k)
            else:
                last[k] = (fn(*args), args if hold else ())
                while len(last) > size:
                    last.popitem(last=False)
            return last[k][0]

        return call

    return wrap


def digest(*arrays: np.ndarray) -> str:
    """A digest of arrays' shapes, types and bytes."""
    h = hashlib.blake2b(digest_size=16)
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(f"{a.shape}{a.dtype}".encode())
        h.update(a.data)
    return h.hexdigest()
