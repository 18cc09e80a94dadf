"""Machine load from /proc/stat, for benches that report how disturbed a timed block was.
Imports nothing but the standard library (bench workers load it before choosing a build)."""

from __future__ import annotations

import os


def busy_cpu_seconds() -> float:
    """CPU seconds spent busy (not idle/iowait) by the whole machine since boot."""
    with open("/proc/stat", encoding="ascii") as fh:
        fields = [int(v) for v in fh.readline().split()[1:]]
    idle = fields[3] + (fields[4] if len(fields) > 4 else 0)
    return (sum(fields[:8]) - idle) / os.sysconf("SC_CLK_TCK")


def own_cpu_seconds() -> float:
    """CPU seconds (user + system) of this process."""
    t = os.times()
    return t.user + t.system


def resident_bytes() -> int:
    """This process's resident memory now (VmRSS of /proc/self/status), bytes; 0 where the
    file has none."""
    with open("/proc/self/status", encoding="ascii") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    return 0
