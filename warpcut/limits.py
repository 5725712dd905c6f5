"""The OS limit behind a failed write, in words: a file-size limit (``ulimit -f``) makes every write past it
fail with ``EFBIG`` (and makes Python's ``tempfile`` find "no usable temporary directory" at 0), which says
nothing of the limit itself."""

from __future__ import annotations

import errno


def file_size_limit() -> int | None:
    """The largest file this process may write (bytes, ``RLIMIT_FSIZE``'s soft limit), or None: no limit."""
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
    except (ImportError, OSError, ValueError):
        return None
    return None if soft == resource.RLIM_INFINITY else int(soft)


def file_size_cause() -> str:
    """The file-size limit, as a cause and its fix: "the file-size limit of this shell (ulimit -f) is N bytes:
    raise it (ulimit -f unlimited) and run again"."""
    limit = file_size_limit()
    size = "set" if limit is None else f"{limit} bytes"
    fix = "raise it (ulimit -f unlimited) and run again"
    return f"the file-size limit of this shell (ulimit -f) is {size}: {fix}"


def write_cause(error: BaseException) -> str | None:
    """The OS cause of a failed write where it is a limit the error's own text does not name: the file-size
    limit (``EFBIG``, or ``tempfile``'s "No usable temporary directory" under a limit), a full disk, a quota;
    None otherwise."""
    code = getattr(error, "errno", None)
    if code == errno.EFBIG or (
        "No usable temporary directory" in str(error) and file_size_limit() is not None
    ):
        return file_size_cause()
    if code == errno.ENOSPC:
        return "the disk is full: free space and run again"
    if code == errno.EDQUOT:
        return "the disk quota is used up: free space and run again"
    return None
