#!/usr/bin/env python3
"""lucerna's tile cache against OpenImageIO's texture system: the same lookups, timed.

    python3 tools/bench/texture_cache_oiio.py [--repeats 3] [--out FILE.md]

Builds the two twins, `texture_lookups.rs` (a cargo bench target: lookups through lucerna's
`TextureCache`) and `texture_lookups_oiio.cpp` (lookups through OpenImageIO's
`TextureSystem`, which Arnold, Cycles' OSL path and RenderMan's OSL use; built against the
system's libopenimageio-dev: `apt-get install libopenimageio-dev`), then runs every
configuration (lookup pattern x cache size x threads) for each program in turn, `--repeats`
times, interleaved so that the shared machine's noise falls on both alike, and reports the
best run of each: lookups per second, their ratio, tiles read and peak memory.

The texture set is eight 2048^2 8-bit RGBA images (128 MiB at full resolution, 171 MiB with
MIP levels); the caches are a quarter of that (32 MiB: tiles are evicted and read again)
and all of it (1024 MiB). The images are made from a formula by each program (OpenImageIO
reads them from `.tx` files it writes once with make_texture, as maketx would; lucerna
writes its own tiled files), outside the timed part.
"""

import argparse
import json
import os
import pathlib
import platform
import subprocess
import sys
import tempfile

ROOT = pathlib.Path(__file__).resolve().parents[2]
PATTERNS = ("coherent", "incoherent", "trilinear")
CACHES = (32, 1024)
THREADS = (1, 2)


def build(work):
    """Paths of the two benchmark programs, built."""
    oiio = work / "texture_lookups_oiio"
    cflags = subprocess.run(["pkg-config", "--cflags", "--libs", "OpenImageIO"],
                            capture_output=True, text=True)
    flags = cflags.stdout.split() if cflags.returncode == 0 else [
        "-lOpenImageIO", "-lOpenImageIO_Util"]
    subprocess.run(["c++", "-O2", "-std=c++17", "-o", str(oiio),
                    str(ROOT / "tools/bench/texture_lookups_oiio.cpp"), *flags, "-lpthread"],
                   check=True)
    out = subprocess.run(["cargo", "bench", "--bench", "texture_lookups", "--no-run",
                          "--message-format=json"], cwd=ROOT, check=True,
                         capture_output=True, text=True).stdout
    rust = next(m["executable"] for m in map(json.loads, out.splitlines())
                if m.get("reason") == "compiler-artifact" and m.get("executable")
                and m["target"]["name"] == "texture_lookups")
    return rust, str(oiio)


def run(program, args):
    out = subprocess.run([program, *args], check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=pathlib.Path)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(dir="/var/tmp") as folder:
        work = pathlib.Path(folder)
        rust, oiio = build(work)
        # OpenImageIO's .tx files are written by its first run: not by a timed one.
        run(oiio, ["--pattern", "incoherent", "--images", "8", "--size", "2048", "--dir", folder])
        rows = []
        for pattern in PATTERNS:
            for cache in CACHES:
                for threads in THREADS:
                    common = ["--pattern", pattern, "--cache-mib", str(cache),
                              "--threads", str(threads)]
                    best = {}
                    for _ in range(args.repeats):
                        for name, program, extra in (("lucerna", rust, []),
                                                     ("oiio", oiio, ["--dir", folder])):
                            r = run(program, common + extra)
                            if name not in best or r["seconds"] < best[name]["seconds"]:
                                best[name] = r
                    rows.append((pattern, cache, threads, best["lucerna"], best["oiio"]))
                    l, o = best["lucerna"], best["oiio"]
                    print(f"{pattern:10} cache {cache:4} MiB, {threads} thread(s): lucerna "
                          f"{l['lookups_per_second'] / 1e6:6.2f} M/s, OpenImageIO "
                          f"{o['lookups_per_second'] / 1e6:6.2f} M/s, ratio "
                          f"{l['lookups_per_second'] / o['lookups_per_second']:.2f}; checksums "
                          f"{l['checksum']:.4f} {o['checksum']:.4f}", flush=True)
    lines = [
        f"Best of {args.repeats} interleaved runs; {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} cores. Lookups per second (millions), tiles read during the "
        "lookups, peak resident memory of the process (MiB).",
        "",
        "| pattern | cache MiB | threads | lucerna M/s | OpenImageIO M/s | lucerna / OIIO | "
        "tiles read lucerna / OIIO | peak MiB lucerna / OIIO | mean value lucerna / OIIO |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for pattern, cache, threads, l, o in rows:
        lines.append(
            f"| {pattern} | {cache} | {threads} | {l['lookups_per_second'] / 1e6:.2f} | "
            f"{o['lookups_per_second'] / 1e6:.2f} | "
            f"{l['lookups_per_second'] / o['lookups_per_second']:.2f} | "
            f"{l['tiles_read']} / {o['tiles_read']} | {l['peak_mib']:.0f} / {o['peak_mib']:.0f} | "
            f"{l['checksum']:.4f} / {o['checksum']:.4f} |")
    table = "\n".join(lines) + "\n"
    print(table)
    if args.out:
        args.out.write_text(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
