"""Writing files so that a failure never leaves a broken one behind: the content goes to a
temporary file in the same folder, which replaces the target only once it is complete (a disk
full, a crash, Ctrl-C half-way leave the previous file as it was).

The temporary file is created private (mode 0o600, tempfile.mkstemp) so that nobody reads it
half-written; before it takes the target's place it gets the mode any file this process opens
gets (0o666 less the umask), as the user expects of a model, a plot or a report.
"""

import os
from pathlib import Path
import tempfile


def umask_mode() -> int:
    """0o666 less this process's umask: the mode ``open`` gives a new file."""
    return 0o666 & ~_umask()


def _umask() -> int:
    # Linux shows the umask in /proc; elsewhere it can only be read by setting it, which for an
    # instant gives a file another thread creates mode 0o666.
    try:
        with open('/proc/self/status') as f:
            for line in f:
                if line.startswith('Umask:'):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def write_atomic(path, write) -> Path:
    """Create or replace ``path`` with what ``write(file)`` writes (a binary file object);
    the folder must exist."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f'.{path.name}.', suffix='.tmp', dir=path.parent)
    try:
        with os.fdopen(fd, 'wb') as f:
            write(f)
            f.flush()
            os.fchmod(f.fileno(), umask_mode())
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    return path


def write_text_atomic(path, text: str) -> Path:
    return write_atomic(path, lambda f: f.write(text.encode()))
