"""JSON reports for `corn-drake bench`: the figures plus the machine they were measured on."""

from __future__ import annotations

import os
import platform
import time
from typing import Any

from corn_drake.storage.atomic_files import write_json


def machine_info() -> dict[str, Any]:
    info: dict[str, Any] = {
        "platform": platform.platform(),
        "python": platform.python_version(),
        "cpu_count": os.cpu_count(),
        "processor": platform.processor(),
    }
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    info["cpu_model"] = line.split(":", 1)[1].strip()
                    break
        info["load_average_at_start"] = os.getloadavg()
    except OSError:
        pass
    info.update(core_topology())
    return info


def core_topology() -> dict[str, int]:
    """How many physical cores this process's usable CPUs are (Linux sysfs; {} elsewhere):
    two hyper-threads of one core share it, so N busy workers on N CPUs that are N / 2 cores
    each run at well under one core's pace. (The benchmarks' results give the usable CPUs.)"""
    try:
        cores = set()
        for cpu in os.sched_getaffinity(0):
            topology = f"/sys/devices/system/cpu/cpu{cpu}/topology"
            with open(f"{topology}/physical_package_id") as f:
                package = f.read().strip()
            with open(f"{topology}/core_id") as f:
                cores.add((package, f.read().strip()))
    except (OSError, AttributeError):
        return {}
    return {"physical_cores": len(cores)}


def write_report(path: str, name: str, results: dict[str, Any]) -> dict[str, Any]:
    report = {
        "benchmark": name,
        "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "machine": machine_info(),
        "results": results,
    }
    write_json(path, report)
    return report
