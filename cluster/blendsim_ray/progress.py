"""The driver's progress bar on stderr: scenes done, running, failed, and the time left.

On a terminal one line is redrawn; otherwise (a log, CI) a line is printed per finished
scene. "running" counts the tasks submitted and not finished, at most one per free slot of
the cluster (Ray queues the rest)."""

import sys
import time


class Progress:
    def __init__(self, total, quiet=False, slots=1, stream=sys.stderr):
        self.total, self.quiet, self.slots, self.stream = total, quiet, slots, stream
        self.count_done = self.count_failed = self.running = 0
        self.start = time.time()
        self.tty = stream.isatty()
        self.drawn = False

    def update(self, running):
        self.running = min(running, self.slots)
        if self.tty and not self.quiet:
            self._draw()

    def done(self):
        self.count_done += 1
        self.running = max(0, self.running - 1)
        self._changed()

    def failed(self, line, ran=True):
        self.count_failed += 1
        self.running = max(0, self.running - ran)
        self._clear()
        print(line, file=self.stream, flush=True)
        self._changed()

    def _changed(self):
        if self.quiet:
            return
        if self.tty:
            self._draw()
        else:
            print(self.text(), file=self.stream, flush=True)

    def text(self):
        finished = self.count_done + self.count_failed
        width = 30
        filled = width * finished // max(1, self.total)
        bar = "#" * filled + "." * (width - filled)
        elapsed = time.time() - self.start
        eta = "--" if finished == 0 else _clock(elapsed / finished * (self.total - finished))
        return (f"[{bar}] {self.count_done}/{self.total} done, {self.running} running, "
                f"{self.count_failed} failed, {_clock(elapsed)} elapsed, ETA {eta}")

    def _draw(self):
        self.stream.write("\r\x1b[2K" + self.text())
        self.stream.flush()
        self.drawn = True

    def _clear(self):
        if self.drawn:
            self.stream.write("\r\x1b[2K")
            self.drawn = False

    def finish(self):
        if self.tty and not self.quiet and self.drawn:
            self.stream.write("\n")
            self.stream.flush()
            self.drawn = False


def _clock(seconds):
    seconds = int(round(seconds))
    return f"{seconds // 60}:{seconds % 60:02d}"
