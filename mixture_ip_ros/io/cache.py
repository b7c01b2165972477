"""The user cache for data sets fetched at run time, and downloads that are checked before
they are kept.

The cache is ``$MIXTURE_IP_CACHE`` or ``$XDG_CACHE_HOME/mixture_ip_ros`` (default
``~/.cache/mixture_ip_ros``). A download goes to a temporary file beside its target and
replaces it only once its sha256 is the pinned one, so nothing half-downloaded or altered is
ever left in the cache.
"""

import hashlib
import os
from pathlib import Path
import tempfile

from mixture_ip_ros.io.files import umask_mode


def cache_dir() -> Path:
    if os.environ.get('MIXTURE_IP_CACHE'):
        return Path(os.environ['MIXTURE_IP_CACHE'])
    base = os.environ.get('XDG_CACHE_HOME') or Path.home() / '.cache'
    return Path(base) / 'mixture_ip_ros'


def sha256_of(path) -> str:
    digest = hashlib.sha256()
    with open(path, 'rb') as f:
        for block in iter(lambda: f.read(1 << 20), b''):
            digest.update(block)
    return digest.hexdigest()


def check_sha256(path, expected: str) -> Path:
    """``path`` if its sha256 is ``expected``, else a ValueError in one line."""
    got = sha256_of(path)
    if got != expected:
        raise ValueError(f'{path}: sha256 {got} is not the pinned {expected}: refused')
    return Path(path)


def download_verified(url: str, target, sha256: str, timeout: float = 60.0) -> Path:
    """Download ``url`` to ``target`` if its sha256 is ``sha256``; a RuntimeError (no network)
    or ValueError (other content) in one line otherwise, with nothing left at ``target``."""
    import urllib.request   # here: the executables read cache_dir at start-up, before any download
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f'.{target.name}.', suffix='.part', dir=target.parent)
    try:
        with os.fdopen(fd, 'wb') as f:
            try:
                with urllib.request.urlopen(url, timeout=timeout) as response:
                    for block in iter(lambda: response.read(1 << 20), b''):
                        f.write(block)
            except OSError as error:
                raise RuntimeError(f'could not download {url}: {error}') from None
        check_sha256(tmp, sha256)
        os.chmod(tmp, umask_mode())      # mkstemp's file is private; the cache is the user's
        os.replace(tmp, target)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return target
