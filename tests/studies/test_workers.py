"""``apf-mpc tune --workers``: what it accepts and the one line for what it does not."""

from __future__ import annotations

import pytest

from pipeline.errors import ConfigError
from pipeline.studies.workers import Workers


@pytest.mark.parametrize("text, kind, count, address", [
    ("local", "local", None, None),
    ("dask-local:2", "dask-local", 2, None),
    ("dask-slurm:16", "dask-slurm", 16, None),
    ("dask://scheduler.example:8786", "dask", None, "tcp://scheduler.example:8786"),
    ("tcp://10.0.0.5:8786", "dask", None, "tcp://10.0.0.5:8786"),
])
def test_what_workers_accepts(text, kind, count, address):
    workers = Workers.parse(text)
    assert (workers.kind, workers.count, workers.address) == (kind, count, address)
    assert workers.local == (kind == "local") and workers.describe()


@pytest.mark.parametrize("text", ["", "dask", "dask-local", "dask-local:0", "dask-local:-1",
                                  "dask-local:99999", "dask-local:two", "ray://x:1",
                                  "dask://x:0", "dask://x:70000", "dask://:8786",
                                  "dask://x y:8786", "slurm:4"])
def test_anything_else_is_one_line_naming_the_option(text):
    with pytest.raises(ConfigError) as info:
        Workers.parse(text)
    assert info.value.key == "--workers" and len(str(info.value).splitlines()) == 1
