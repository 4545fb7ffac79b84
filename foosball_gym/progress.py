"""Progress of a long command: a bar on a terminal, a plain line now and then elsewhere.

Written to standard error, so that what a command prints on standard output (the lines scripts
read) stays as it was. The bar is tqdm's, from the ``train`` extra; without tqdm, or where the
stream is not a terminal (a log file, a pipe, CI), a line such as
``eval: 40/100 episodes (40 %), 0:00:12 elapsed, about 0:00:18 left`` is written every
``every_s`` seconds, and one more at the end, so that a log shows the job going and ending.
"""

from __future__ import annotations

import sys
import time
from datetime import timedelta
from typing import Any, TextIO

# Often enough that a log shows a job going on, rarely enough that an hour fills no screen.
EVERY_S = 15.0


def _duration(seconds: float) -> str:
    return str(timedelta(seconds=round(seconds)))


def is_terminal(stream: Any) -> bool:
    isatty = getattr(stream, "isatty", None)
    try:
        return bool(isatty and isatty())
    except ValueError:  # a closed stream
        return False


class Progress:
    """Count ``total`` units of work named ``what`` (``"eval"``), ``initial`` of them done.

    Args:
        total: how many units the work takes.
        what: the job's name, at the start of each line or the bar.
        unit: what a unit is (``"episodes"``).
        initial: units done before this count starts (a resumed training's steps).
        stream: where to write (standard error).
        every_s: seconds between two plain lines.
        enabled: False: write nothing at all.
    """

    def __init__(
        self,
        total: int,
        what: str,
        unit: str = "",
        *,
        initial: int = 0,
        stream: TextIO | None = None,
        every_s: float = EVERY_S,
        enabled: bool = True,
    ) -> None:
        self.total = total
        self.what = what
        self.unit = unit
        self.done = initial
        self.note = ""
        self.stream = stream if stream is not None else sys.stderr
        self.every_s = every_s
        self.enabled = enabled
        self._initial = initial
        self._start = time.monotonic()
        self._last_line = self._start
        self._bar: Any = None
        if enabled and is_terminal(self.stream):
            try:
                from tqdm import tqdm
            except ImportError:
                pass
            else:
                self._bar = tqdm(
                    total=total,
                    initial=initial,
                    desc=what,
                    unit=f" {unit}" if unit else "it",
                    file=self.stream,
                    dynamic_ncols=True,
                    leave=False,
                )

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()

    def set_note(self, note: str) -> None:
        """Show ``note`` (``"last evaluation 95.0 %"``) beside the count from now on."""
        self.note = note
        if self._bar is not None:
            self._bar.set_postfix_str(note, refresh=False)

    def set_total(self, total: int) -> None:
        """The work takes ``total`` units after all (a fit that finds more to do)."""
        self.total = total
        if self._bar is not None:
            self._bar.total = total
            self._bar.refresh()

    def update(self, n: int = 1) -> None:
        """``n`` more units done."""
        self.done += n
        if not self.enabled:
            return
        if self._bar is not None:
            self._bar.update(n)
            return
        now = time.monotonic()
        if now - self._last_line >= self.every_s:
            self._last_line = now
            self._write(self.line(now))

    def line(self, now: float | None = None, ended: bool = False) -> str:
        """Where the work stands, as one plain line; ``ended``: where it ended, with no time
        left to guess (a training that reached its target ends short of its total)."""
        now = time.monotonic() if now is None else now
        elapsed = now - self._start
        count = f"{self.done:,}/{self.total:,}{' ' + self.unit if self.unit else ''}"
        if self.total:
            count += f" ({100 * self.done / self.total:.0f} %)"
        early = ended and self.done < self.total
        parts = [f"{self.what}: {'ended at ' if early else ''}{count}"]
        if self.note:
            parts.append(self.note)
        parts.append(f"{_duration(elapsed)} elapsed")
        done_here = self.done - self._initial
        if not ended and 0 < done_here and self.done < self.total:
            left = elapsed / done_here * (self.total - self.done)
            parts.append(f"about {_duration(left)} left")
        return ", ".join(parts)

    def close(self) -> None:
        """End the count: the bar is cleared, or a last plain line says where it ended."""
        if not self.enabled:
            return
        self.enabled = False
        if self._bar is not None:
            self._bar.close()
        else:
            self._write(self.line(ended=True))

    def _write(self, text: str) -> None:
        print(text, file=self.stream, flush=True)
