"""A terminal progress bar usable as the renderer's ``progress(fraction, message)`` callback.

    bar = ProgressBar()
    result = render(scene, settings, progress=bar)
    bar.close()

Writes one self-overwriting line to stderr (``\\r``) when stderr is a terminal;
otherwise (logs, CI, pipes) it prints a plain line only when the phase changes
or every 10 %, so log files stay short.  The phase is the message without its
counters: ``tracing tile 3/130`` and ``tracing tile 4/130`` are one phase
(:func:`phase_of`).  ``quiet=True`` prints nothing.
"""
from __future__ import annotations

import re
import sys
import time

__all__ = ["ProgressBar", "phase_of"]

_COUNTER = re.compile(r"\s*\d+\s*/\s*\d+|(?<=pass)\s+\d+")


def phase_of(message: str) -> str:
    """The phase a progress message belongs to: the message with its ``N/M`` counters and the pass
    number of ``pass N: ...`` removed."""
    return _COUNTER.sub("", message or "").strip()


class ProgressBar:
    """Callable ``bar(fraction in [0, 1], message str)`` drawing ``[#####.....]  42%  message  12.3 s``."""

    def __init__(self, *, stream=None, width: int = 30, quiet: bool = False, min_interval: float = 0.1):
        self.stream = sys.stderr if stream is None else stream
        self.width = int(width)
        self.quiet = quiet
        self.min_interval = float(min_interval)
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.t0 = time.perf_counter()
        self._last_draw = -1e9
        self._last_msg = None
        self._last_decile = -1
        self._drawn = False

    def __call__(self, fraction: float, message: str = "") -> None:
        if self.quiet:
            return
        f = min(max(float(fraction), 0.0), 1.0)
        now = time.perf_counter()
        elapsed = now - self.t0
        phase = phase_of(message)
        if self.tty:
            # Redraw at most every min_interval seconds, always at the end and on a new phase
            if now - self._last_draw < self.min_interval and f < 1.0 and phase == self._last_msg:
                return
            filled = int(round(f * self.width))
            line = f"[{'#' * filled}{'.' * (self.width - filled)}] {100 * f:5.1f}%  {message}  {elapsed:6.1f} s"
            self.stream.write("\r" + line[:200].ljust(80))
            self._drawn = True
        else:
            decile = int(f * 10)
            if phase == self._last_msg and decile == self._last_decile:
                return
            self.stream.write(f"{100 * f:5.1f}%  {message}  {elapsed:.1f} s\n")
            self._last_decile = decile
        self.stream.flush()
        self._last_draw, self._last_msg = now, phase

    def note(self, text: str) -> None:
        """Print ``text`` as a line of its own (above the bar on a terminal: the bar redraws below it)."""
        if self.quiet:
            return
        if self.tty and self._drawn:
            self.stream.write("\r" + " " * 80 + "\r")
        self.stream.write(text + "\n")
        self.stream.flush()
        self._drawn = False
        self._last_draw = -1e9

    def close(self) -> None:
        """End the bar's line (call once the render finished or failed)."""
        if self.tty and self._drawn and not self.quiet:
            self.stream.write("\n")
            self.stream.flush()
        self._drawn = False
