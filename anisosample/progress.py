"""Progress reporting for long work (synthesis, table builds, sweeps, renders)."""

from __future__ import annotations

import os
import sys

from tqdm.auto import tqdm


def progress(iterable=None, *, total=None, desc=None, disable=None, **kwargs):
    """A tqdm bar on stderr; disabled when ``ANISOSAMPLE_PROGRESS=0`` or when asked."""
    if disable is None:
        disable = os.environ.get("ANISOSAMPLE_PROGRESS", "1") == "0"
    return tqdm(
        iterable,
        total=total,
        desc=desc,
        disable=disable,
        file=sys.stderr,
        dynamic_ncols=True,
        **kwargs,
    )
