"""A memo that changes no value: a pure function of large inputs, called with the same
inputs by several units of one scene on one worker, computes once.

`last_call(key)` keeps the last call's result under `key(*args)`; being one of the
package's decorators, it enters no row's hash (`bench.codehash`): it decides no value.
"""

from __future__ import annotations

import functools
import hashlib
from collections.abc import Callable

import numpy as np


def last_call(key: Callable[..., tuple]):
    """Decorate a pure function: a call whose `key(*args)` equals the last call's returns
    the last result (its arguments are held with it, so that an `id` in a key cannot be
    reused by another object while it is remembered)."""

    def wrap(fn):
        last: dict = {}

        @functools.wraps(fn)
        def call(*args):
            k = key(*args)
            if last.get("key") != k:
                last.clear()
                last.update(key=k, value=fn(*args), args=args)
            return last["value"]

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
