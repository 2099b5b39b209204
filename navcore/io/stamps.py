"""Time stamps of manifests."""
from __future__ import annotations

import datetime as dt
import os


def build_time() -> str:
    """UTC time stamp for manifests; SOURCE_DATE_EPOCH (reproducible-builds convention) pins it
    so that reruns give byte-identical assets."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    t = dt.datetime.fromtimestamp(int(epoch), dt.timezone.utc) if epoch else dt.datetime.now(dt.timezone.utc)
    return t.isoformat(timespec="seconds")
