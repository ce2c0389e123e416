"""The version of a file, for per-process caches of what is derived from it (a parsed scenario, a converted
road network): a warm sweep worker reads the same files run after run."""

from __future__ import annotations

import stat
from pathlib import Path

#: a file's absolute path, size, modification and status-change times (ns) and inode: an edit or an atomic
#: replace changes it
FileVersion = tuple[str, int, int, int, int]


def file_version(path: Path) -> FileVersion | None:
    """The version of the regular file at `path`; None when there is none (missing, a directory, ...)."""
    try:
        st = path.stat()
    except OSError:
        return None
    if not stat.S_ISREG(st.st_mode):
        return None
    return (str(path.absolute()), st.st_size, st.st_mtime_ns, st.st_ctime_ns, st.st_ino)
