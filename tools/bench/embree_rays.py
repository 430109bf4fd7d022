#!/usr/bin/env python3
"""Ray throughput of Mitsuba 3's Embree (llvm_ad_rgb) on the ray sets of tools/bench/throughput.rs,
to put lucerna's own figures (`cargo bench --bench throughput`) next to a production BVH on
the same machine.

    .venv/bin/python tools/bench/embree_rays.py [SCENE]   (default: the Cornell box)

The sets follow tools/bench/throughput.rs: a camera ray through each pixel centre of a 1024x1024
image (coherent closest hit); from each camera hit, a cosine-distributed direction around
the normal (incoherent closest hit); segments from the camera hits to the first emitter's
centre (coherent shadow) and between two random camera hits (incoherent shadow). Mitsuba
traces each set as one wavefront (Embree's 16-wide ray packets on AVX-512); the figure is
the best of five runs after an untimed one that compiles the kernel, with 1 and 2 threads.
The time includes Dr.Jit reading the rays and writing the answers, so it slightly
understates Embree's own speed.
"""
import argparse
import sys
import tempfile
import time
from pathlib import Path

import lucerna_tools as lt
from lucerna_tools import mitsuba_export

SIDE = 1024
RUNS = 5


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene", nargs="?", default=str(lt.ROOT / "scenes/cornell-box/cornell-box.gltf"))
    args = parser.parse_args()
    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")
    import drjit as dr

    with tempfile.TemporaryDirectory() as workdir:
        scene_file = Path(workdir) / "scene.lucerna"
        lt.convert(args.scene, scene_file)
        scene = mi.load_dict(mitsuba_export.scene_dict(scene_file, SIDE, SIDE, workdir))

    index = dr.arange(mi.UInt32, SIDE * SIDE)
    pixel = mi.Point2f((mi.Float(index % SIDE) + 0.5) / SIDE, (mi.Float(index // SIDE) + 0.5) / SIDE)
    coherent, _ = scene.sensors()[0].sample_ray(0.0, 0.5, pixel, mi.Point2f(0.5))
    camera_hits = scene.ray_intersect(coherent)
    hits = dr.gather(type(camera_hits), camera_hits, dr.compress(camera_hits.is_valid()))
    count = dr.width(hits.t)
    rng = mi.load_dict({"type": "independent"})
    rng.seed(7, count)
    bounce = mi.Frame3f(hits.n).to_world(mi.warp.square_to_cosine_hemisphere(rng.next_2d()))
    incoherent = hits.spawn_ray(bounce)
    origins = incoherent.o
    emitters = [shape for shape in scene.shapes() if shape.is_emitter()]
    target = mi.Point3f(emitters[0].bbox().center()) if emitters else mi.Point3f(0, scene.bbox().max.y, 0)

    def segments(to):
        ray = mi.Ray3f(origins, to - origins)
        ray.maxt = mi.Float(1.0)
        return ray

    partner = dr.gather(mi.Point3f, origins, mi.UInt32(rng.next_1d() * count) % count)
    sets = {"coherent": (coherent, segments(target)), "incoherent": (incoherent, segments(partner))}
    for closest, shadow in sets.values():
        dr.eval(closest, shadow)

    def rays_per_second(trace, rays):
        def run():
            dr.eval(trace(rays))
            dr.sync_thread()
        run()
        best = float("inf")
        for _ in range(RUNS):
            start = time.perf_counter()
            run()
            best = min(best, time.perf_counter() - start)
        return dr.width(rays.o) / best / 1e6

    print(f"Mitsuba {mi.__version__} llvm_ad_rgb (Embree), {Path(args.scene).name}, {count} camera hits")
    print("| rays | closest 1 thr (Mrays/s) | closest 2 thr | shadow 1 thr (Mrays/s) | shadow 2 thr |")
    print("|---|---|---|---|---|")
    for name, (closest, shadow) in sets.items():
        figures = {}
        for threads in (1, 2):
            dr.set_thread_count(threads)
            figures[threads] = (rays_per_second(lambda r: scene.ray_intersect_preliminary(r).t, closest),
                                rays_per_second(scene.ray_test, shadow))
        print(f"| {name} | {figures[1][0]:.2f} | {figures[2][0]:.2f} | {figures[1][1]:.2f} | {figures[2][1]:.2f} |")


if __name__ == "__main__":
    main()
