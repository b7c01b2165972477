"""Writing files so that a failure never leaves a broken one behind: the content goes to a
temporary file in the same folder, which replaces the target only once it is complete (a disk
full, a crash, Ctrl-C half-way leave the previous file as it was)."""

import os
from pathlib import Path
import tempfile


def write_atomic(path, write) -> Path:
    """Create or replace ``path`` with what ``write(file)`` writes (a binary file object);
    the folder must exist."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f'.{path.name}.', suffix='.tmp', dir=path.parent)
    try:
        with os.fdopen(fd, 'wb') as f:
            write(f)
            f.flush()
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
