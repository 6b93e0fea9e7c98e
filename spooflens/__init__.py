"""spooflens: forensic analysis of GNSS spoofing in vehicle logs.

Pipeline: file -> readers -> EpochTable -> navigation -> detectors -> verdict -> Rerun recording and report.
"""

import os
from pathlib import Path

__version__ = "0.1.0"


def _huge_pages_stall() -> bool:
    """Whether the kernel compacts memory on the fault of a region asking for transparent huge pages.

    numpy asks for them on every large array (madvise). Where the kernel then compacts on the first
    touch (THP defrag "always", "madvise" or "defer+madvise"; the machine our benchmark figures come
    from has "madvise"), those touches stall: by hand, reading a 4 h voyage took 3.8-4.6 s with them and
    3.0 s without, a 1 h log end to end about 10 % longer."""
    try:
        setting = Path("/sys/kernel/mm/transparent_hugepage/defrag").read_text()
    except OSError:
        return False
    chosen = setting[setting.find("[") + 1 : setting.find("]")]
    return chosen in ("always", "madvise", "defer+madvise")


if _huge_pages_stall():
    os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", "0")  # read once, when numpy is imported; a user's own wins
