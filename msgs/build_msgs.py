"""Build and install the ppod_msgs interface package into the running virtual environment.

Run with the venv's interpreter (``run.sh`` does): ``.venv/bin/python msgs/build_msgs.py``.
It configures msgs/ with CMake against the ament/rosidl wheels installed in this venv, builds with
Ninja and installs into the venv's prefix, so ``from ppod_msgs.msg import PlateMotion`` works.
Idempotent: a stamp of the sources and the interpreter skips a build that is up to date.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import shutil
import subprocess
import sys
import sysconfig
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _source_hash() -> str:
    h = hashlib.sha256()
    for path in sorted(HERE.rglob("*")):
        if path.is_file() and path.suffix in {".msg", ".srv", ".action", ".txt", ".xml", ".py"}:
            h.update(path.relative_to(HERE).as_posix().encode())
            h.update(path.read_bytes())
    h.update(sys.executable.encode())
    h.update(sys.version.encode())
    return h.hexdigest()


def _ament_prefixes() -> list[str]:
    """Every prefix in this environment that holds share/ament_index (the wheels' install roots)."""
    candidates = [sys.prefix, sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]]
    out: list[str] = []
    for c in candidates:
        if (Path(c) / "share" / "ament_index").is_dir() and c not in out:
            out.append(c)
    return out


def _importable() -> bool:
    probe = "import ppod_msgs.msg, ppod_msgs.srv, ppod_msgs.action"
    return subprocess.run([sys.executable, "-c", probe], capture_output=True).returncode == 0


def _tool(name: str) -> str:
    bindir = Path(sys.executable).parent
    for cand in (bindir / name, shutil.which(name)):
        if cand and Path(cand).exists():
            return str(cand)
    raise SystemExit(f"build_msgs: '{name}' not found; install it (pip install -e '.[msgs]' provides it)")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--force", action="store_true", help="rebuild even if the stamp is current")
    parser.add_argument("--quiet", action="store_true", help="print only the summary line")
    args = parser.parse_args(argv)

    if sys.prefix == sys.base_prefix:
        raise SystemExit("build_msgs: run this with a virtual environment's python (it installs into it)")
    build_dir = Path(sys.prefix) / "var" / "ppod_msgs_build"
    stamp = build_dir / "ppod_msgs.stamp"
    digest = _source_hash()
    if not args.force and stamp.is_file() and stamp.read_text() == digest and _importable():
        print("ppod_msgs: up to date")
        return 0

    prefixes = _ament_prefixes()
    if not prefixes:
        raise SystemExit("build_msgs: no ament prefix in this venv; install the ROS wheels first "
                         "(pip install -e '.[msgs]')")
    env = dict(os.environ)
    env["AMENT_PREFIX_PATH"] = os.pathsep.join(prefixes)
    env["CMAKE_PREFIX_PATH"] = os.pathsep.join(prefixes)
    env["PATH"] = str(Path(sys.executable).parent) + os.pathsep + env.get("PATH", "")
    # The wheels' libraries live in <venv>/lib; generators load some of them while building.
    env["LD_LIBRARY_PATH"] = os.pathsep.join([str(Path(sys.prefix) / "lib"), env.get("LD_LIBRARY_PATH", "")])
    cmake, ninja = _tool("cmake"), _tool("ninja")
    build_dir.mkdir(parents=True, exist_ok=True)
    cache = build_dir / "CMakeCache.txt"
    if cache.exists() and str(HERE) not in cache.read_text(errors="replace"):
        shutil.rmtree(build_dir)
        build_dir.mkdir(parents=True)

    t0 = time.monotonic()
    out = subprocess.DEVNULL if args.quiet else None
    log = build_dir / "build.log"
    steps = [
        [cmake, "-G", "Ninja", str(HERE), f"-DCMAKE_MAKE_PROGRAM={ninja}",
         f"-DCMAKE_INSTALL_PREFIX={sys.prefix}", f"-DCMAKE_PREFIX_PATH={';'.join(prefixes)}",
         f"-DPython3_EXECUTABLE={sys.executable}", "-DPython3_FIND_VIRTUALENV=ONLY",
         "-DBUILD_TESTING=OFF", "-DCMAKE_BUILD_TYPE=Release"],
        [ninja, "-C", str(build_dir)],
        [ninja, "-C", str(build_dir), "install"],
    ]
    with open(log, "w") as logf:
        for cmd in steps:
            logf.write("$ " + " ".join(cmd) + "\n")
            logf.flush()
            proc = subprocess.run(cmd, cwd=build_dir, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                  text=True)
            logf.write(proc.stdout)
            if out is None:
                tail = [ln for ln in proc.stdout.splitlines() if ln.strip()][-2:]
                for ln in tail:
                    print(f"  {ln}")
            if proc.returncode != 0:
                print(proc.stdout[-4000:], file=sys.stderr)
                raise SystemExit(f"build_msgs: '{Path(cmd[0]).name}' failed (exit {proc.returncode}); full log: {log}")
    if not _importable():
        raise SystemExit(f"build_msgs: built, but 'import ppod_msgs' fails in this venv; log: {log}")
    stamp.write_text(digest)
    print(f"ppod_msgs: built and installed into {sys.prefix} in {time.monotonic() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
