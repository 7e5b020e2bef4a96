"""How large a cache a bake writes, and the refusal of one that cannot be written."""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Sequence

from ..errors import ArgumentError
from .plan import ResolvedBake

__all__ = ["MAX_CACHE_BYTES", "FRAME_STATE_BYTES", "cache_bytes", "check_size"]

#: Largest cache a single bake writes [bytes]; a longer range is refused up front (bake it in
#: chunks, ``batch --chunk-frames``). The points are streamed to disk
#: (:data:`~cloth_usd.usd.write.FLUSH_BYTES` held at a time), so this bounds the file, not memory.
MAX_CACHE_BYTES = 16 * 2 ** 30
#: Memory a bake holds per frame whatever its garments [bytes]: time codes, the body's motion
#: and each garment's frame transform, read for the whole range up front (measured: about
#: 13 KiB a frame for the sample's shirt, whose 20000-frame bake peaked at 438 MiB, 40000 at 699 MiB).
FRAME_STATE_BYTES = 16 * 2 ** 10
#: A text (``.usda``) cache is about 3.2 times its binary size, and is staged in a binary one.
_USDA_FACTOR = 4.5


def cache_bytes(frames: int, vertices: Sequence[int]) -> int:
    """Estimated size [bytes] of a cache of ``frames`` time samples of garments with these
    vertex counts: float32 points (12 bytes a vertex) and a 24-byte extent per frame."""
    return int(frames) * sum(12 * int(n) + 24 for n in vertices)


def _available_memory() -> int | None:
    """Bytes of memory available to a new allocation (Linux ``MemAvailable``), or None."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _size(n: float) -> str:
    return f"{n / 2 ** 30:.3g} GiB" if n >= 2 ** 30 else f"{n / 2 ** 20:.3g} MiB"


def _free_disk(folder: Path) -> int | None:
    try:
        return shutil.disk_usage(folder).free
    except OSError:
        return None


def check_size(plan: ResolvedBake, limit: int | None, *, output: str | Path | None = None) -> None:
    """ArgumentError, before anything is computed, for a cache that cannot be written.

    Args:
        limit: the largest cache [bytes]; None: :data:`MAX_CACHE_BYTES`, and then also the
            free space of ``output``'s folder (for the file) and the memory available (for
            :data:`FRAME_STATE_BYTES` a frame).
        output: the cache layer to write.
    """
    count = plan.frames.count()
    vertices = [g.rest_points.shape[0] for g in plan.chosen]
    size = cache_bytes(count, vertices)
    cap = MAX_CACHE_BYTES if limit is None else int(limit)
    what = f"--frames {plan.frames.spec()}" if plan.frames_given else f"frames {plan.frames}"
    figure = (f"{what}: {count} frames x {sum(vertices)} garment vertices make a cache of about "
              f"{_size(size)}")
    if size > cap:
        raise ArgumentError(f"{figure}, more than the {cap / 2 ** 30:.3g} GiB a single bake builds; bake a "
                            "smaller range, or split it with `cloth-usd batch --chunk-frames N`")
    if limit is not None:
        return
    if output is not None:
        folder = Path(os.path.abspath(output)).parent
        need = int(size * _USDA_FACTOR) if Path(output).suffix == ".usda" else size
        free = _free_disk(folder)
        if free is not None and need > free:
            text = "" if need == size else f" ({_size(need)} as text)"
            raise ArgumentError(f"{figure}{text}, more than the {_size(free)} free in '{folder}'; free some "
                                "space or write it elsewhere")
    available = _available_memory()
    held = count * FRAME_STATE_BYTES * max(1, len(vertices))
    if available is not None and held > available:
        raise ArgumentError(f"{what}: {count} frames hold about {_size(held)} of motion in memory, "
                            f"more than the {_size(available)} available; bake a smaller range, or "
                            "split it with `cloth-usd batch --chunk-frames N`")
