"""The JSON results a benchmark script writes with ``--json`` (default
``benchmarks/results/<name>.json``) and ``benchmarks/report.py`` turns into the tables of
docs/benchmarks.md: the script's name, the machine (cores, CPU), the command's arguments
and what it printed (``rows`` and the ratios it reports)."""

from __future__ import annotations

import argparse
import json
import os
import platform
from pathlib import Path
from typing import Any

RESULTS = Path(__file__).resolve().parent / "results"


def cpu_model() -> str:
    """The CPU's model name (Linux ``/proc/cpuinfo``; ``platform.processor()`` elsewhere)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def add_json(ap: argparse.ArgumentParser, name: str) -> None:
    """The ``--json PATH`` option, default ``benchmarks/results/<name>.json``."""
    ap.add_argument("--json", type=Path, default=RESULTS / f"{name}.json",
                    help=f"write the figures here (default benchmarks/results/{name}.json; regenerate the docs "
                         "with python benchmarks/report.py)")


def _plain(value: Any) -> Any:
    """NumPy scalars and arrays, paths and sets as JSON."""
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, (set, tuple)):
        return list(value)
    return str(value)


def write(path: Path, script: str, args: argparse.Namespace, **figures: Any) -> None:
    """Write one run's figures to ``path`` with the machine and the arguments."""
    argv = {k: str(v) if isinstance(v, Path) else v for k, v in vars(args).items() if k != "json"}
    out = {"benchmark": script, "cores": os.cpu_count(), "cpu": cpu_model(), "args": argv, **figures}
    Path(path).write_text(json.dumps(out, indent=1, default=_plain) + "\n")
    print(f"wrote {path}")
