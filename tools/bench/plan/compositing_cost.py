"""What the compositing layers cost: render seconds (interleaved pairs, median ratio) and
callgrind instructions of the render loop with every layer lucerna writes (`all`, the lobe
splits, light groups, Cryptomatte) against the beauty alone, on the Cornell box and the MIS
plates. Writes tools/bench/plan/results/compositing_cost.md.

    .venv/bin/python tools/bench/plan/compositing_cost.py [--repeats 5] [--quick]
"""
import argparse
import platform
import tempfile
from pathlib import Path

import plan_bench as pb

EVERYTHING = "all,lobes,lightgroups,crypto"
CASES = [
    ("Cornell box: every layer / beauty only", pb.CORNELL, (256, 256),
     {"aov": "beauty"}, {"aov": EVERYTHING}),
    ("Cornell box: lobes / beauty only", pb.CORNELL, (256, 256),
     {"aov": "beauty"}, {"aov": "lobes"}),
    ("Cornell box: light groups / beauty only", pb.CORNELL, (256, 256),
     {"aov": "beauty"}, {"aov": "lightgroups"}),
    ("Cornell box: Cryptomatte / beauty only", pb.CORNELL, (256, 256),
     {"aov": "beauty"}, {"aov": "crypto"}),
    ("MIS plates: every layer / beauty only", pb.PLATES, (240, 160),
     {"aov": "beauty"}, {"aov": EVERYTHING}),
]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        rows = pb.feature_costs(Path(tmp), args.repeats, args.quick, CASES)
    lines = ["# What the compositing layers cost", "",
             f"Machine: {platform.machine()}, 2 cores, shared. Command: "
             "`.venv/bin/python tools/bench/plan/compositing_cost.py`. Render seconds: median "
             f"of {args.repeats} pairs run back to back in alternating order, and the median of "
             "the per-pair ratios; instructions: callgrind, render loop only (64x64, 8 spp, one "
             f"thread). Every layer = `--aov {EVERYTHING}`.", "",
             "| case | spp | seconds A | seconds B | B / A (time) | instructions A | instructions B | B / A (instructions) |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        ir = (f"{r['instructions_a']:,} | {r['instructions_b']:,} | **{r['instruction_ratio']:.3f}**"
              if r["instruction_ratio"] else "- | - | -")
        lines.append(f"| {r['case']} | {r['spp']} | {r['seconds_a']:.2f} | {r['seconds_b']:.2f} | "
                     f"**{r['ratio']:.3f}** | {ir} |")
    out = pb.HERE / "results" / "compositing_cost.md"
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
