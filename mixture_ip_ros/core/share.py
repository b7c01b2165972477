"""Where the package's shared files (models/, config/) live, installed or in a checkout."""

from pathlib import Path
import sys

_PACKAGE = 'mixture_ip_ros'


def share_dir() -> Path:
    """The checkout root when running from source, else <prefix>/share/mixture_ip_ros."""
    checkout = Path(__file__).resolve().parents[2]
    if (checkout / 'package.xml').is_file():
        return checkout
    return Path(sys.prefix) / 'share' / _PACKAGE


def model_path(name: str) -> Path:
    return share_dir() / 'models' / name


def config_path(name: str) -> Path:
    return share_dir() / 'config' / name
