"""Where the package's Hydra config folder is: ``pipeline/conf`` in an installed package (the
wheel ships the configs there), else the repository's ``conf/`` beside the package (a checkout
or an editable install). Read by the configuration and by the registries that list its files
(the method presets, the claim catalogue)."""

from __future__ import annotations

from pathlib import Path


def _conf_dir() -> Path:
    packaged = Path(__file__).resolve().parent / "conf"
    if packaged.is_dir():
        return packaged
    return Path(__file__).resolve().parent.parent / "conf"


#: The Hydra config folder the entry points compose from.
CONF_DIR = _conf_dir()
#: Hydra's primary config (``config_name``): ``CONF_DIR / f"{CONFIG_NAME}.yaml"``.
CONFIG_NAME = "config"
