"""Frame ranges: the one value type of ``--frames``, parsed once at the edge (CLI, job file).

``START:END[:STEP]`` is inclusive. :func:`parse_frames` reads it; :func:`parse_time_codes`
also reads a comma list of time codes and ranges (``render --frames``). Shape letters: T frames.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ..errors import ArgumentError

__all__ = ["FrameRange", "parse_frames", "parse_time_codes"]


@dataclass(frozen=True)
class FrameRange:
    """An inclusive range of time codes."""

    start: float
    """First time code."""
    end: float
    """Last time code (included when ``start + k * step`` reaches it)."""
    step: float = 1.0
    """Time codes between frames (positive)."""

    def count(self) -> int:
        """T, the number of time codes, without making them."""
        return int(np.floor((self.end - self.start) / self.step + 1e-9)) + 1

    def times(self) -> np.ndarray:
        """(T,) float64 time codes from start to end inclusive."""
        return self.start + self.step * np.arange(self.count(), dtype=np.float64)

    def chunks(self, size: int) -> list["FrameRange"]:
        """Consecutive ranges of at most ``size`` frames that together make this one."""
        times = self.times()
        return [FrameRange(float(times[lo]), float(times[min(lo + size, times.shape[0]) - 1]), self.step)
                for lo in range(0, times.shape[0], size)]

    def spec(self) -> str:
        """``START:END``, or ``START:END:STEP`` when the step is not 1: as a user writes it."""
        text = f"{self.start:.10g}:{self.end:.10g}"
        return text if self.step == 1.0 else f"{text}:{self.step:.10g}"

    def __str__(self) -> str:
        """``START:END:STEP``, as :func:`parse_frames` reads it (the form provenance records)."""
        return f"{self.start:.10g}:{self.end:.10g}:{self.step:.10g}"


_FRAMES = re.compile(r"^\s*(-?[\d.]+)\s*:\s*(-?[\d.]+)\s*(?::\s*(-?[\d.]+)\s*)?$")


def parse_frames(text: str) -> FrameRange:
    """Parse ``START:END[:STEP]`` (inclusive); raises ArgumentError naming ``--frames``."""
    m = _FRAMES.match(text)
    try:
        if not m:
            raise ValueError
        start, end = float(m.group(1)), float(m.group(2))
        step = float(m.group(3)) if m.group(3) else 1.0
    except ValueError:
        raise ArgumentError(f"--frames '{text}': expected START:END or START:END:STEP, "
                            "e.g. 1001:1100 or 1:48:2") from None
    if step <= 0:
        raise ArgumentError(f"--frames '{text}': STEP must be positive")
    if end < start:
        raise ArgumentError(f"--frames '{text}': empty range (END is before START)")
    return FrameRange(start, end, step)


def parse_time_codes(text: str) -> tuple[float, ...]:
    """Time codes from a comma list whose items are time codes or ``START:END[:STEP]`` ranges
    (``1001,1030,1060``, ``1001:1096:24``, ``1001:1010,1050``), in the order given.

    Raises:
        ArgumentError: naming ``--frames`` and the item at fault.
    """
    out: list[float] = []
    for item in text.split(","):
        if ":" in item:
            out.extend(float(t) for t in parse_frames(item).times())
            continue
        try:
            out.append(float(item))
        except ValueError:
            raise ArgumentError(f"--frames '{text}': '{item.strip()}' is not a time code or START:END[:STEP] "
                                "(e.g. 1001,1030,1060 or 1001:1096:24)") from None
    return tuple(out)
