"""Where built FMUs are kept, the one rule the builder
(:mod:`fmu_models.export.build`) and a run's look-up
(:mod:`fmu_models.built`) share, importing nothing heavy."""
from __future__ import annotations

import os
from pathlib import Path

__all__ = ["cache_root"]


def cache_root() -> Path:
    """$FNN_COSIM_CACHE, else build/fmu-cache in a source checkout, else ~/.cache/fnn-cosim."""
    if os.environ.get("FNN_COSIM_CACHE"):
        return Path(os.environ["FNN_COSIM_CACHE"])
    repo = Path(__file__).resolve().parents[1]
    if (repo / "pyproject.toml").exists():
        return repo / "build" / "fmu-cache"
    return Path.home() / ".cache" / "fnn-cosim"
