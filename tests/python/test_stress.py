"""The quick subset of the stress suite (tools/experiments/stress/stress.py --quick): the Cornell box
far away and tiny, duplicated and zero-area triangles, zero-length normals, a sealed thin
box, a grazing camera, GGX roughness 1e-4, a tiny bright light, 256 lights, NaN and Inf
input, the memory limit, and glass (index-matched, extreme indices and absorption, the glass
box 1e7 units away, panes seen at grazing angles); each rendered by the binary and checked
as the full suite does."""
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_quick_stress_subset_passes():
    proc = subprocess.run([sys.executable, str(ROOT / "tools/experiments/stress/stress.py"), "--quick"],
                          capture_output=True, text=True, timeout=1200, env=dict(os.environ))
    print(proc.stdout)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "15 of 15 cases pass" in proc.stdout
