"""lucerna against an independent renderer: Mitsuba 3 renders the Cornell box from the same
geometry (tools/mitsuba_cornell.py); the difference between the renderers must be within
2x the difference between two Mitsuba seeds, i.e. no visible bias."""
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))
import mitsuba_cornell  # noqa: E402

BIN = os.environ.get("LUCERNA_BIN", str(ROOT / "target" / "release" / "lucerna"))


def test_cornell_box_agrees_with_mitsuba():
    r = mitsuba_cornell.compare(spp=256, width=64, height=64, binary=BIN)
    assert r["ratio"] <= 2.0, r
    for lucerna, mitsuba in zip(r["mean_lucerna"], r["mean_mitsuba"]):
        assert abs(lucerna - mitsuba) <= 0.01 * mitsuba, r
