"""Progress of a long compression on stderr: :class:`Progress` (``compress(..., progress=True)``).

While the first chunk of the path compiles, one line ``compiling … 12 s``; then, per phase, a
bar with the probe displacement (µm), the probe force (pN), the accepted steps and the elapsed
wall time (s).  On a terminal the line is rewritten in place about once a second: a daemon
thread keeps the elapsed time moving while JAX compiles or a chunk runs, and the chunks are
sized to take about half a second (``socbjax._protocol``), so steps, displacement and force
move at least once a second.  Elsewhere (a log file, a pipe) a line is written at most every
10 s, plus each phase's last, so logs stay short.
"""

from __future__ import annotations

import math
import sys
import threading
import time

__all__ = ["Progress", "TICK_S", "LOG_EVERY_S", "plural"]

TICK_S = 1.0  # terminal refresh of the elapsed time (s)
LOG_EVERY_S = 10.0  # at most one line per this many seconds where stderr is not a terminal


def plural(n: int, word: str, many: str | None = None) -> str:
    """``"1 point"``, ``"2 points"`` (``many``: an irregular plural) for progress and status lines."""
    return f"{n} {word if n == 1 else (many or word + 's')}"


def _isatty(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):  # no isatty, or a closed stream
        return False


class Progress:
    """The progress of one compression: a line on ``stream`` (``progress=True``; default
    stderr), or a user callable ``progress(phase, u, steps, done)`` called between chunks of
    the path (phase name, probe displacement µm, accepted steps of the phase, whether the
    phase ended).  ``total`` (µm) is the full probe travel, the bar's length."""

    def __init__(self, progress, total: float, stream=None):
        self.callback = progress if callable(progress) else None
        self.enabled = bool(progress) and self.callback is None
        self.total, self.t0 = total, time.perf_counter()
        self.stream = sys.stderr if stream is None else stream
        self.tty = self.enabled and _isatty(self.stream)
        self._lock = threading.Lock()  # the ticker thread and the driver write the same line
        self._line = None  # elapsed s -> the text of the current line; None: nothing to refresh
        self._width = 0  # characters of the unfinished line on the terminal (0: at a line start)
        self._logged = -math.inf  # when a line was last written to a non-terminal
        self._stop = threading.Event()
        self._ticker = None

    @property
    def active(self) -> bool:
        """Whether anything is reported (the path then runs in short chunks)."""
        return self.enabled or self.callback is not None

    def start(self) -> None:
        """Show ``compiling … 3 s`` until the first report (terminal: once a second; elsewhere:
        every 10 s), from the first tick on: a program already compiled shows no such line."""
        if not self.enabled or self._ticker is not None:
            return
        with self._lock:
            self._line = lambda t: f"compiling … {t:.0f} s"
        self._ticker = threading.Thread(target=self._tick, name="socbjax-progress", daemon=True)
        self._ticker.start()

    def __call__(self, phase: str, u: float, steps: int, force: float = math.nan, done: bool = False) -> None:
        """Report phase ``phase`` at probe displacement ``u`` (µm) and probe force ``force``
        (pN) after ``steps`` accepted steps; ``done``: the phase ended (its line is kept)."""
        if self.callback is not None:
            self.callback(phase, u, steps, done)
            return
        if not self.enabled:
            return
        frac = min(max(u / self.total, 0.0), 1.0) if self.total else 1.0
        force = round(force, 9) + 0.0  # the settle phase's round-off (1e-23 pN) shown as 0, never as -0
        head = f"{phase:>9s} [{'#' * int(30 * frac):<30s}] u = {u:7.4f} µm  F = {force:9.4g} pN  steps {steps:5d}"
        self._show(lambda t: f"{head}  {t:6.1f} s", final=done)

    def close(self) -> None:
        """Stop the ticker and end an unfinished line (also after an error or an interrupt)."""
        self._stop.set()
        if self._ticker is not None:
            self._ticker.join()
            self._ticker = None
        with self._lock:
            if self._width:
                self.stream.write("\n")
                self.stream.flush()
            self._line, self._width = None, 0

    def _tick(self) -> None:
        while not self._stop.wait(TICK_S):
            self._show(None)

    def _show(self, line, final: bool = False) -> None:
        """Write ``line`` (None: the current one, with its elapsed time refreshed)."""
        with self._lock:
            if line is not None:
                self._line = line
            if self._line is None:
                return
            now = time.perf_counter()
            text = self._line(now - self.t0)
            if self.tty:  # in place; padded over a longer previous text
                self.stream.write("\r" + text.ljust(self._width) + ("\n" if final else ""))
                self._width = 0 if final else len(text)
            elif final or now - self._logged >= LOG_EVERY_S:
                self.stream.write(text + "\n")
                self._logged = now
            else:
                return
            self.stream.flush()
            if final:  # the ticker must not repeat a finished phase
                self._line = None
