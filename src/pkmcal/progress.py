"""Progress bars for long work (planning, cuckoo search, simulation, reproductions, the demo).

Library loops report progress through plain callbacks ``progress(done, total)``
(:data:`Progress`); a job of several stages (``pkmcal plan``: workspace box, planning model,
candidates, selection) takes ``announce(stage) -> Progress | None`` (:data:`Stages`). They
never print anything themselves.

The command line turns them into a :class:`ProgressBar`: a `tqdm <https://tqdm.github.io>`_
bar on **standard error**, shown only when

* standard output *and* standard error are terminals (a redirected or piped output, a CI log
  or a test sees nothing),
* ``--quiet`` was not given, and
* the work is still running after :data:`DELAY_S` seconds (quick runs stay clean;
  ``PKMCAL_PROGRESS_DELAY`` sets another delay).

The bar is removed when the work ends (``leave=False``), so what stays on the screen is the
command's own output. tqdm is imported only when a bar is actually shown.
"""

from __future__ import annotations

import os
import sys
import time
from typing import Callable

#: progress(done, total): ``done`` units of work out of ``total`` (an upper bound when the
#: loop may stop early, as the exchange algorithms do).
Progress = Callable[[int, int], None]
#: announce(stage) → the progress callback of that stage (or None: nobody is listening).
Stages = Callable[[str], "Progress | None"]

#: A bar appears only once the work has run this long (seconds); the environment variable
#: ``PKMCAL_PROGRESS_DELAY`` (seconds) overrides it.
DELAY_S = 0.5
#: What a bar shows: counts and elapsed time, no percentage or time-to-go (the totals of the
#: exchange algorithms are upper bounds: they stop when no exchange improves the set).
BAR_FORMAT = "{desc}: {n_fmt}/{total_fmt} {unit} |{bar}| {elapsed}"


def bars_enabled(quiet: bool = False) -> bool:
    """Whether a progress bar may be shown: not ``quiet`` and both standard output and
    standard error are terminals."""
    return not quiet and _isatty(sys.stdout) and _isatty(sys.stderr)


def _isatty(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):   # a replaced or closed stream
        return False


def _delay() -> float:
    text = os.environ.get("PKMCAL_PROGRESS_DELAY", "").strip()
    try:
        return max(0.0, float(text)) if text else DELAY_S
    except ValueError:
        return DELAY_S


class ProgressBar:
    """A progress bar on standard error for one command (module docstring).

    Call it as a :data:`Progress` callback, or use :meth:`stage` as a :data:`Stages`
    announcer; :meth:`note` prints a line above the bar (or plainly when no bar is shown).
    A context manager: the bar is removed on exit. When bars are disabled every method but
    :meth:`note` does nothing, and nothing is imported. The tqdm bar itself is created at
    the first update after :data:`DELAY_S` seconds.
    """

    def __init__(self, label: str, *, quiet: bool = False, unit: str = "steps"):
        self.label, self.unit, self.quiet = label, unit, quiet
        self.enabled = bars_enabled(quiet)
        self._t0 = time.monotonic()
        self._delay = _delay()
        self._bar = None
        self._stage = ""
        self._done, self._total = 0, None

    # -- Progress / Stages --------------------------------------------------------------

    def __call__(self, done: int, total: int) -> None:
        if not self.enabled:
            return
        self._done, self._total = int(done), (int(total) if total else None)
        bar = self._shown()
        if bar is None:
            return
        if bar.total != self._total or self._done < bar.n:
            bar.total = self._total
            bar.reset(total=self._total)
        bar.update(self._done - bar.n)

    def stage(self, name: str) -> Progress | None:
        """Make ``name`` the current stage (its counter starts from zero) and return the
        callback of that stage (None when bars are disabled)."""
        if not self.enabled:
            return None
        self._stage, self._done, self._total = name, 0, None
        if self._bar is not None:
            self._bar.set_description_str(self._description(), refresh=False)
            self._bar.total = None
            self._bar.reset(total=None)
        return self

    # -- text and the end ---------------------------------------------------------------

    def note(self, message: str) -> None:
        """Print ``message`` on standard error (above the bar when one is shown), unless quiet."""
        if self.quiet:
            return
        if self._bar is not None:
            self._bar.write(message, file=sys.stderr)
        else:
            print(message, file=sys.stderr, flush=True)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __enter__(self) -> "ProgressBar":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _description(self) -> str:
        return f"{self.label}: {self._stage}" if self._stage else self.label

    def _shown(self):
        """The tqdm bar, created (and so imported) once the work has run :data:`DELAY_S`
        and while it is not finished (a bar born complete would only flash)."""
        unfinished = self._total is None or self._done < self._total
        if self._bar is None and unfinished and time.monotonic() - self._t0 >= self._delay:
            from tqdm import tqdm

            tqdm.monitor_interval = 0      # no monitor thread: a process pool may fork this process later
            self._bar = tqdm(desc=self._description(), total=self._total, initial=self._done, unit=self.unit,
                             file=sys.stderr, leave=False, dynamic_ncols=True, mininterval=0.2,
                             bar_format=BAR_FORMAT)
        return self._bar


__all__ = ["BAR_FORMAT", "DELAY_S", "Progress", "ProgressBar", "Stages", "bars_enabled"]
