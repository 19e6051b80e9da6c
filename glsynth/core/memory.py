"""How much memory this machine can still give, for checks made before a large allocation."""

from pathlib import Path


def available_bytes() -> int | None:
    """The kernel's estimate of the memory available to new allocations without swapping
    (MemAvailable of /proc/meminfo); None where it cannot be read (not Linux)."""
    try:
        lines = Path("/proc/meminfo").read_text().splitlines()
    except OSError:
        return None
    for line in lines:
        name, _, value = line.partition(":")
        if name == "MemAvailable":
            return int(value.split()[0]) * 1024
    return None
