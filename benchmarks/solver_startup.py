"""Start-up of a small CLI call (``ppod bench solver --startup``).

Runs ``ppod field config/motions/Sink.yaml --json OUT --quiet`` (21 x 21, the default grid) in
fresh processes, interleaved with the same command under ``PPOD_AOT=0`` (numba's JIT kernel instead
of the ahead-of-time one: the path as it was before issue 13's seventh pass). Wall time with
``time.perf_counter`` around each process, CPU (user + sys) from ``RUSAGE_CHILDREN``; the two JSON
outputs must agree apart from their timing fields. On a busy machine compare CPU: wall includes
waiting for a core.
"""

from __future__ import annotations

import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The timed command after the ``ppod`` executable (the JSON target is appended).
COMMAND = ["field", "config/motions/Sink.yaml", "--quiet", "--json"]
#: Fields of the JSON that hold timings (they differ from run to run).
TIMING_FIELDS = ("seconds", "setup_seconds")
#: Variants: label -> value of PPOD_AOT.
VARIANTS = {"ahead-of-time kernel": "1", "JIT kernel (PPOD_AOT=0)": "0"}


def _ppod() -> list[str]:
    script = Path(sys.executable).with_name("ppod")
    return [str(script)] if script.is_file() else [sys.executable, "-m", "ppod_nodes.cli.main"]


def _once(env_value: str, target: Path) -> tuple[float, float]:
    env = dict(os.environ, PPOD_AOT=env_value)
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(_ppod() + COMMAND + [str(target)], cwd=ROOT, env=env, check=True, timeout=300)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)


def _without_timings(path: Path) -> dict:
    data = json.loads(path.read_text())
    return {k: v for k, v in data.items() if k not in TIMING_FIELDS}


def measure(runs: int = 9) -> list[list[str]]:
    """Rows: variant, runs, wall min / median s, CPU median s, load before -> after."""
    times: dict[str, list[tuple[float, float]]] = {label: [] for label in VARIANTS}
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        outputs = {label: Path(tmp) / f"{i}.json" for i, label in enumerate(VARIANTS)}
        for k in range(runs):
            for label, value in VARIANTS.items():
                times[label].append(_once(value, outputs[label]))
            print(f"startup: run {k + 1}/{runs}", file=sys.stderr, flush=True)
        first, *rest = (_without_timings(p) for p in outputs.values())
        same = all(r == first for r in rest)
    load1 = os.getloadavg()[0]
    print(f"startup: outputs {'identical' if same else 'DIFFER'} apart from {', '.join(TIMING_FIELDS)}", flush=True)
    if not same:
        raise RuntimeError("ppod field gave different fields with the ahead-of-time and the JIT kernel")
    rows = []
    for label, values in times.items():
        wall = [w for w, _ in values]
        cpu = [c for _, c in values]
        rows.append([label, str(runs), f"{min(wall):.3f}", f"{statistics.median(wall):.3f}",
                     f"{statistics.median(cpu):.3f}", f"{load0:.2f} -> {load1:.2f}"])
    return rows
