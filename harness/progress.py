"""Progress of a long job, on stderr, that a person can follow on a terminal and in a log.

One class, :class:`Progress`, for every long job of the harness (a sweep, a nightly run,
a reference render, a calibration). stdout stays reserved for the command's result.

* On a terminal (stderr is a TTY) it draws a ``rich`` bar with done/total, elapsed time,
  the ETA, the failures so far and a short detail line.
* Otherwise (cron, CI, ``2> file``) it writes one timestamped line per event, at most one
  every ``every_s`` seconds, and always the first and the last::

      2026-12-01T15:40:02Z sweep: 12/216 configurations (5.6 %), 1 failed, elapsed 0:01:10, ETA 0:19:30; jade_veins N=64

* ``SSLPV_PROGRESS=bar|lines|off`` in the environment overrides the choice (tests use
  ``lines``); ``enabled=False`` (``--no-progress``) turns it off.

The ETA is the elapsed time per unit of work times the work left, unless the caller
knows better (a reference render predicts it from its noise, ``eta_s=``).
"""

from __future__ import annotations

import os
import sys
import time
from datetime import datetime, timezone

__all__ = ["Progress", "progress_mode", "format_duration"]

MODES = ("bar", "lines", "off")


def progress_mode(stream=None, enabled=True):
    """``"bar"``, ``"lines"`` or ``"off"`` for ``stream`` (default stderr)."""
    if not enabled:
        return "off"
    env = os.environ.get("SSLPV_PROGRESS", "").strip().lower()
    if env in MODES:
        return env
    stream = sys.stderr if stream is None else stream
    try:
        tty = stream.isatty()
    except (AttributeError, ValueError):
        tty = False
    return "bar" if tty else "lines"


def format_duration(seconds):
    """``h:mm:ss`` for a number of seconds (``?`` when unknown)."""
    if seconds is None or not seconds == seconds or seconds == float("inf") or seconds < 0:
        return "?"
    s = int(round(seconds))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}"


class Progress:
    """Progress of one job: ``with Progress("sweep", total=216) as p: p.advance(detail=...)``.

    Parameters
    ----------
    what : str
        The job's name, first word of every line (``sweep``, ``nightly``, ``reference jade_veins``).
    total : int or float
        Units of work in all (may be changed later with :meth:`update`).
    unit : str
        What a unit is, for the lines (``configurations``, ``seeds``).
    enabled : bool
        False: print nothing (the ``--no-progress`` flag).
    stream : file, optional
        Where to write (default ``sys.stderr``).
    every_s : float
        In ``lines`` mode, at most one line per this many seconds (first and last always).
    clock : callable, optional
        Seconds, monotonic (tests pass a fake clock).
    """

    def __init__(self, what, total, *, unit="configurations", enabled=True, stream=None, every_s=5.0,
                 clock=None):
        self.what, self.unit = str(what), unit
        self.total = total
        self.done, self.failed = 0, 0
        self.detail = ""
        self.eta_s = None
        self.stream = sys.stderr if stream is None else stream
        self.mode = progress_mode(self.stream, enabled)
        self.every_s = float(every_s)
        self._clock = clock or time.monotonic
        self._t0 = self._clock()
        self._last_t = None                # when the last line was written (lines mode)
        self._last_state = None            # (done, total, failed, detail) of that line
        self._bar = self._task = None

    # ----------------------------------------------------------------- context

    def __enter__(self):
        if self.mode == "bar":
            from rich.console import Console
            from rich.progress import (BarColumn, MofNCompleteColumn, Progress as RichProgress, TextColumn,
                                       TimeElapsedColumn)

            self._bar = RichProgress(TextColumn(f"[bold]{self.what}"), BarColumn(), MofNCompleteColumn(),
                                     TimeElapsedColumn(), TextColumn("ETA {task.fields[eta]}"),
                                     TextColumn("{task.fields[failed]}"), TextColumn("{task.description}"),
                                     console=Console(file=self.stream), transient=False)
            self._bar.__enter__()
            self._task = self._bar.add_task("", total=self.total, eta="?", failed="")
        else:
            self._emit(force=True)
        return self

    def __exit__(self, *exc):
        if self._bar is not None:
            self._bar.__exit__(*exc)
            self._bar = None
        elif self._last_state != self._state():
            self._emit(force=True)             # the final state, if throttling held it back
        return False

    # ----------------------------------------------------------------- updates

    def advance(self, n=1, *, failed=0, detail=None):
        """``n`` more units done (``failed`` of them failed); ``detail``: what was just done."""
        self.done += n
        self.failed += failed
        if detail is not None:
            self.detail = str(detail)
        self._refresh()

    def update(self, *, done=None, total=None, failed=None, detail=None, eta_s=None):
        """Set any of the counters directly; ``eta_s`` replaces the rate-based ETA."""
        if done is not None:
            self.done = done
        if total is not None:
            self.total = total
        if failed is not None:
            self.failed = failed
        if detail is not None:
            self.detail = str(detail)
        self.eta_s = eta_s if eta_s is not None else self.eta_s
        self._refresh()

    def log(self, message):
        """One timestamped line (below the bar on a terminal); printed even when throttled."""
        if self.mode == "off":
            return
        if self._bar is not None:
            self._bar.console.print(f"{self.what}: {message}", markup=False, highlight=False)
        else:
            self._write(f"{_stamp()} {self.what}: {message}")

    # ----------------------------------------------------------------- internals

    def elapsed(self):
        return self._clock() - self._t0

    def eta(self):
        """Seconds left: the caller's estimate, or the rate so far times the work left."""
        if self.eta_s is not None:
            return self.eta_s
        if not self.done or not self.total:
            return None
        return self.elapsed() / self.done * max(self.total - self.done, 0)

    def _line(self):
        pct = f" ({100.0 * self.done / self.total:.1f} %)" if self.total else ""
        done = f"{self.done:g}" if isinstance(self.done, float) else str(self.done)
        if self.total is not None:
            done += "/" + (f"{self.total:g}" if isinstance(self.total, float) else str(self.total))
        text = f"{self.what}: {done} {self.unit}{pct}"
        if self.failed:
            text += f", {self.failed} failed"
        text += f", elapsed {format_duration(self.elapsed())}, ETA {format_duration(self.eta())}"
        if self.detail:
            text += f"; {self.detail}"
        return text

    def _refresh(self):
        if self.mode == "off":
            return
        if self._bar is not None:
            self._bar.update(self._task, completed=self.done, total=self.total, description=self.detail,
                             eta=format_duration(self.eta()),
                             failed=f"{self.failed} failed" if self.failed else "")
        else:
            self._emit(force=self.total is not None and self.done >= self.total)

    def _emit(self, force=False):
        if self.mode != "lines":
            return
        now = self._clock()
        if not force and self._last_t is not None and now - self._last_t < self.every_s:
            return
        self._write(f"{_stamp()} {self._line()}")
        self._last_state, self._last_t = self._state(), now

    def _state(self):
        return (self.done, self.total, self.failed, self.detail)

    def _write(self, text):
        try:
            self.stream.write(text + "\n")
            self.stream.flush()
        except (OSError, ValueError):        # a closed or full log must not end the job
            pass


def _stamp():
    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
