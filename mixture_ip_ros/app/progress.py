"""Progress on a console: the fits of training's held-out curves (:func:`text_progress`), the
time of each of its stages (:class:`Stages`, shown by :func:`text_stages`), and an evaluation's
folds as each one ends (:func:`text_lines`)."""

from contextlib import contextmanager
import sys
import time


def _on_terminal(stream) -> bool:
    isatty = getattr(stream, 'isatty', None)
    return bool(isatty and isatty())


def text_progress(stream=None, what='choosing K'):
    """The progress of the K curves on ``stream`` (default: stderr): on a terminal a bar redrawn
    in place; otherwise (a log file, CI) a line at each quarter of the fits, since every redraw
    would be a line of its own there. Returns ``show(done, total, K)``."""
    return _TextProgress(sys.stderr if stream is None else stream, what)


class _TextProgress:
    """:func:`text_progress`'s ``show``; off a terminal it remembers the last quarter shown."""

    WIDTH = 30

    def __init__(self, stream, what):
        self.stream, self.what = stream, what
        self.on_terminal = _on_terminal(stream)
        self.quarter = 0

    def __call__(self, done, total, K):
        if self.on_terminal:
            filled = int(self.WIDTH * done / total)
            self.stream.write(f'\r{self.what} K={K:<2d} '
                              f'[{"#" * filled}{"." * (self.WIDTH - filled)}] {done}/{total}')
            if done == total:
                self.stream.write('\n')
        else:
            quarter = 4 * done // total
            if quarter <= self.quarter:
                return
            self.quarter = quarter
            self.stream.write(f'{self.what}: {done}/{total} fits ({25 * quarter} %)\n')
        self.stream.flush()


class Stages:
    """Where training's time goes: the wall time of each named stage (s) in ``seconds``, and
    each stage's start and end shown by ``show(name, seconds)`` (seconds None at the start;
    None: nothing shown). Used as ``with stages('choosing K'): ...``."""

    def __init__(self, show=None):
        self.seconds = {}
        self.show = show

    @contextmanager
    def __call__(self, name):
        if self.show:
            self.show(name, None)
        t0 = time.perf_counter()
        try:
            yield
        finally:
            spent = time.perf_counter() - t0
            self.seconds[name] = round(self.seconds.get(name, 0.0) + spent, 3)
            if self.show:
                self.show(name, spent)


def text_stages(stream=None):
    """Training's stages on ``stream`` (default: stderr): a stage's name as it starts on a
    terminal (its fits' bar follows, text_progress), and a line with its time as it ends."""
    stream = sys.stderr if stream is None else stream
    on_terminal = _on_terminal(stream)

    def show(name, seconds):
        if seconds is None:
            if on_terminal:
                stream.write(f'{name} ...\n')
        else:
            stream.write(f'{name}: {seconds:.1f} s\n')
        stream.flush()
    return show


def text_lines(stream=None):
    """``show(line)``: each line written whole on ``stream`` (default: stderr) as it comes, for
    steps that each take long enough to be worth a line (an evaluation's folds)."""
    stream = sys.stderr if stream is None else stream

    def show(line):
        stream.write(line + '\n')
        stream.flush()
    return show
