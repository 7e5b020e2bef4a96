"""How large a cache a bake builds in memory, and the refusal of one too large."""

from __future__ import annotations

from typing import Sequence

from ..errors import ArgumentError
from .plan import ResolvedBake

__all__ = ["MAX_CACHE_BYTES", "cache_bytes", "check_size"]

#: Largest cache a single bake builds [bytes]: the layer is held in memory until it is
#: saved, so a longer range is refused up front (bake it in chunks, ``batch --chunk-frames``).
MAX_CACHE_BYTES = 16 * 2 ** 30


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


def check_size(plan: ResolvedBake, limit: int | None) -> None:
    """ArgumentError, before anything is computed, for a cache too large to build in memory.

    Args:
        limit: the largest cache [bytes]; None: :data:`MAX_CACHE_BYTES` or the memory
            available, whichever is less.
    """
    count = plan.frames.count()
    vertices = [g.rest_points.shape[0] for g in plan.chosen]
    size = cache_bytes(count, vertices)
    cap = MAX_CACHE_BYTES if limit is None else int(limit)
    available = _available_memory() if limit is None else None
    why = None
    if size > cap:
        why = f"more than the {cap / 2 ** 30:.3g} GiB a single bake builds"
    elif available is not None and size > available:
        why = f"more than the {available / 2 ** 30:.3g} GiB of memory available"
    if why is None:
        return
    what = f"--frames {plan.frames.spec()}" if plan.frames_given else f"frames {plan.frames}"
    raise ArgumentError(
        f"{what}: {count} frames x {sum(vertices)} garment vertices make a cache of about "
        f"{size / 2 ** 30:.3g} GiB, {why}; bake a smaller range, or split it with "
        "`cloth-usd batch --chunk-frames N`")
