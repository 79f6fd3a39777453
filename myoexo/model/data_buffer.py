"""One numpy index that reads entries of several ``MjData`` arrays at once.

MuJoCo allocates every per-model array of an ``mjData`` from one main buffer
(``mjData.buffer``, ``nbuffer`` bytes, "all pointers point in it"), so a strided float64 view
that starts at the lowest of the arrays spans them all, and ``view[index]`` gathers entries of
several arrays (``qpos``, ``qvel``, ``actuator_force``, ``sensordata``, ...) in one numpy call,
instead of one attribute lookup, one index and one concatenation per array.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

__all__ = ["buffer_gather"]


def buffer_gather(
    data: mujoco.MjData, gathered: Sequence[tuple[str | None, np.ndarray]]
) -> tuple[np.ndarray, np.ndarray]:
    """``(view, index)`` with ``view[index]`` the entries ``[(field, indices), ...]`` of
    *data*, in that order (a ``None`` field: placeholder entries, which read the view's first
    entry).

    ``view`` is read-only, its base is one of ``data``'s own arrays (it keeps ``data``
    alive), and only the indexed entries, which lie inside their arrays, are ever read.

    Raises:
        RuntimeError: If the arrays are not float64 vectors in one buffer of
            ``data.nbuffer`` bytes.
    """
    fields = [f for f, _ in gathered if f is not None]
    arrays = {f: getattr(data, f) for f in fields}
    addrs = {f: a.__array_interface__["data"][0] for f, a in arrays.items()}
    lowest = min(fields, key=addrs.__getitem__)
    start = addrs[lowest]
    end = max(addrs[f] + a.nbytes for f, a in arrays.items())
    in_one_buffer = end - start <= data.nbuffer and all(
        a.dtype == np.float64 and a.ndim == 1 and (addrs[f] - start) % 8 == 0
        for f, a in arrays.items()
    )
    if not in_one_buffer:
        raise RuntimeError(f"MjData arrays {fields} are not in one buffer")
    view = np.lib.stride_tricks.as_strided(
        arrays[lowest], shape=((end - start) // 8,), strides=(8,), writeable=False
    )
    index = np.concatenate(
        [
            np.zeros(len(idx), dtype=np.intp) if f is None else (addrs[f] - start) // 8 + idx
            for f, idx in gathered
        ]
    ).astype(np.intp)
    return view, index
