"""Memory figures of this process for the fuzz tests (Linux /proc; getrusage elsewhere).

VmHWM is the peak RSS of this process's own address space, reset on exec; getrusage's ru_maxrss is
not: a child started from a large pytest process reports the parent's size as its own peak.
"""
import resource


def reset_peak_rss() -> None:
    """Start a new peak-memory window (Linux: ``clear_refs`` 5 resets VmHWM); else keep the lifetime peak."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        pass


def _status_mb(field: str) -> float:
    """A memory figure of this process from /proc/self/status (peak RSS from getrusage elsewhere)."""
    try:
        with open("/proc/self/status") as f:
            return next(int(line.split()[1]) for line in f if line.startswith(field + ":")) / 1024.0
    except (OSError, StopIteration):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def peak_rss_mb() -> float:
    return _status_mb("VmHWM")


def rss_mb() -> float:
    return _status_mb("VmRSS")
