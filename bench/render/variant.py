"""Choosing a Mitsuba variant safely: each candidate is probed in a child process.

Mitsuba's LLVM variant aborts the whole process with libLLVM 15/16 (and is off with 14),
so a variant is only ever set in this process after a child has rendered with it. The
answer is remembered per machine and library versions, so the probe is paid once.
"""

from __future__ import annotations

import glob
import json
import os
import platform
import re
import shutil
import subprocess
import sys
from importlib.metadata import version
from pathlib import Path

from bench import BenchError
from bench.files import write_text_atomic

PROBE_CODE = """
import sys, mitsuba as mi
mi.set_variant(sys.argv[1])
scene = mi.cornell_box()
scene['sensor']['film'].update(width=16, height=16)
mi.render(mi.load_dict(scene), spp=2)
print('probe ok')
"""
PROBE_TIMEOUT_S = 300


def configure_llvm() -> str | None:
    """Point Dr.Jit at the newest libLLVM >= 17 unless DRJIT_LIBLLVM_PATH is already set.

    Dr.Jit reads the variable once, at first use, so this runs before mitsuba is imported.
    """
    if "DRJIT_LIBLLVM_PATH" not in os.environ:
        found = []
        for path in glob.glob("/usr/lib/*/libLLVM*.so*") + glob.glob(
            "/usr/lib/llvm-*/lib/libLLVM*.so*"
        ):
            m = re.search(r"libLLVM(?:-|\.so\.)(\d+)", path)
            if m and int(m.group(1)) >= 17:
                found.append((int(m.group(1)), path))
        if found:
            os.environ["DRJIT_LIBLLVM_PATH"] = max(found)[1]
    return os.environ.get("DRJIT_LIBLLVM_PATH")


def probe(variant: str) -> tuple[bool, str]:
    """Render a tiny scene with `variant` in a child process: (works, why not)."""
    try:
        r = subprocess.run(
            [sys.executable, "-c", PROBE_CODE, variant],
            capture_output=True,
            text=True,
            timeout=PROBE_TIMEOUT_S,
            env=os.environ.copy(),
        )
    except subprocess.TimeoutExpired:
        return False, f"probe timed out after {PROBE_TIMEOUT_S} s"
    if r.returncode == 0 and "probe ok" in r.stdout:
        return True, ""
    lines = [ln for ln in (r.stderr + r.stdout).splitlines() if ln.strip()]
    return False, (lines[-1][:200] if lines else f"probe exited with code {r.returncode}")


def _gpu_present() -> bool:
    return shutil.which("nvidia-smi") is not None or Path("/dev/nvidiactl").exists()


def resolve_variant(requested: str, memo_dir: Path) -> tuple[str, str]:
    """The variant to render with, and one line saying which and why."""
    llvm = configure_llvm()
    memo_path = Path(memo_dir) / ".variant-probes.json"
    key = "|".join(
        [
            platform.node(),
            sys.executable,
            version("mitsuba"),
            version("drjit"),
            str(llvm),
            str(_gpu_present()),
        ]
    )
    try:
        memo = json.loads(memo_path.read_text())
    except (OSError, ValueError):
        memo = {}
    known = memo.get(key, {})

    def works(variant: str) -> tuple[bool, str]:
        if variant == "scalar_rgb":
            return True, ""
        if variant not in known:
            known[variant] = probe(variant)
            memo[key] = known
            try:
                memo_path.parent.mkdir(parents=True, exist_ok=True)
                write_text_atomic(memo_path, json.dumps(memo, indent=1))
            except OSError:
                pass  # the memo is only a speed-up
        return tuple(known[variant])

    if requested != "auto":
        ok, why = works(requested)
        if not ok:
            raise BenchError(
                f"variant {requested} does not render here ({why}); try --variant auto"
            )
        return requested, f"render variant {requested} (requested)"
    reasons = []
    candidates = (["cuda_ad_rgb"] if _gpu_present() else []) + ["llvm_ad_rgb"]
    if not _gpu_present():
        reasons.append("no GPU")
    for v in candidates:
        ok, why = works(v)
        if ok:
            detail = (
                f"probe rendered with {llvm}" if v == "llvm_ad_rgb" else "probe rendered on the GPU"
            )
            return v, f"render variant {v} (auto: {'; '.join([*reasons, detail])})"
        reasons.append(f"{v} failed: {why}")
    return "scalar_rgb", f"render variant scalar_rgb (auto fallback: {'; '.join(reasons)})"
