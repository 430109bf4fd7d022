"""Shared helpers of lucerna's experiment and benchmark tools: render through the binary,
read EXRs with OpenImageIO, error metrics, cached references, labelled image grids.

Error metric (docs/architecture.md, "Accuracy and speed"): relMSE = mean over pixels and
channels of (x - ref)^2 / (ref^2 + 0.01); efficiency = 1 / (seconds x relMSE).

Installed into the development venv in editable mode (tools/pyproject.toml), so every tool
and test imports it as `lucerna_tools`, and its modules as `lucerna_tools.gltf_writer`,
`lucerna_tools.mitsuba_export`, `lucerna_tools.mitsuba_compare`.
"""
import copy
import hashlib
import json
import math
import os
import subprocess
import tempfile
import tomllib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
BINARY = os.environ.get("LUCERNA_BIN", str(ROOT / "target" / "release" / "lucerna"))
CACHE = Path(os.environ.get("LUCERNA_CACHE", ROOT / "tools" / ".cache"))


def read_exr(path):
    """(channels by name as float64 arrays, header attributes as a dict)."""
    import OpenImageIO as oiio
    inp = oiio.ImageInput.open(str(path))
    if not inp:
        raise RuntimeError(oiio.geterror())
    try:
        spec = inp.spec()
        pixels = np.array(inp.read_image(0, 0, 0, spec.nchannels, "float"), dtype=np.float64)
        channels = {name: pixels[:, :, i] for i, name in enumerate(spec.channelnames)}
        header = {a.name: a.value for a in spec.extra_attribs}
        return channels, header
    finally:
        inp.close()


def rgb(channels, layer=None):
    names = ["R", "G", "B"] if layer is None else [f"{layer}.{c}" for c in "RGB"]
    return np.stack([channels[n] for n in names], axis=-1)


def run(cmd):
    """Runs a lucerna command; a failure raises with lucerna's own message (file, element,
    reason), not only its exit status."""
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, cmd))}: exit status {done.returncode}: "
                           f"{done.stderr.strip() or 'no message'}")


def render(scene, out, resolution, **settings):
    """Renders `scene` (None: the default scene) to `out` with settings given as keyword
    arguments (underscores for dashes: max_depth=10). Returns (beauty, header, channels)."""
    cmd = [BINARY, "render"] + ([str(scene)] if scene else [])
    cmd += ["-o", str(out), "-q", "--resolution", f"{resolution[0]}x{resolution[1]}"]
    for key, value in settings.items():
        cmd += [f"--{key.replace('_', '-')}", str(value)]
    run(cmd)
    channels, header = read_exr(out)
    return rgb(channels), header, channels


def convert(scene, out):
    """Writes lucerna's scene file of `scene` (glTF, USD or a scene file) to `out`: the form
    tools edit and export to Mitsuba."""
    run([BINARY, "convert", str(scene), "-o", str(out)])


def settings_of(header):
    return tomllib.loads(header["lucerna/settings"])


def relmse(x, ref):
    return float(np.mean((x - ref) ** 2 / (ref ** 2 + 0.01)))


def mse(x, ref):
    return float(np.mean((x - ref) ** 2))


def mape(x, ref):
    return float(np.mean(np.abs(x - ref) / (np.abs(ref) + 0.01)))


# Samples per pixel of the render that fingerprints what lucerna renders for a reference: a
# pass of 16 and the start of the next, so that the pass structure is exercised too.
FINGERPRINT_SPP = 20
FIRST_SEED = 1_000_003


def fingerprint(scene, resolution, **settings):
    """SHA-256 of the image lucerna renders at the reference's resolution and settings with
    FINGERPRINT_SPP samples from the reference's first seed, bit for bit. References are
    keyed by it rather than by the binary: a change of the renderer that changes what it
    converges to changes these samples too (every pixel's first samples run the same code
    as the reference's), while a rebuild that renders the same image keeps the reference
    (the Cornell box's takes four minutes). A change confined to samples past the 20th of a
    pixel would go unnoticed; none of the estimator's code depends on that index."""
    with tempfile.TemporaryDirectory() as tmp:
        _, _, channels = render(scene, Path(tmp) / "fingerprint.exr", resolution, spp=FINGERPRINT_SPP,
                                aov="beauty", **dict(settings, seed=FIRST_SEED))
    digest = hashlib.sha256()
    for name in sorted(channels):
        digest.update(name.encode() + np.ascontiguousarray(channels[name], dtype=np.float32).tobytes())
    return digest.hexdigest()


def reference(scene, resolution, spp, **settings):
    """A high-sample reference, cached under tools/.cache by what lucerna renders (its
    fingerprint), scene contents, resolution, sample count and settings. Returns (image,
    info) where info records the sample count, the render seconds and the reference's own
    noise: its expected relMSE against the true image.

    The reference is the mean of two renders of half the samples each with different seeds
    (independent scrambles), so their difference measures its noise: with equal halves,
    E[relMSE(a, b)] is twice a half's noise and four times the mean's. (The variance layer
    would overstate it: it sees the samples as independent, not Sobol's stratification.)"""
    scene_bytes = Path(scene).read_bytes() if scene else b"default"
    key = hashlib.sha256(fingerprint(scene, resolution, **settings).encode() + scene_bytes
                         + json.dumps([resolution, spp, sorted(settings.items())]).encode()).hexdigest()[:16]
    CACHE.mkdir(parents=True, exist_ok=True)
    image_path = CACHE / f"ref-{key}.npy"
    meta = CACHE / f"ref-{key}.json"
    if not (image_path.exists() and meta.exists()):
        half = spp // 2
        halves, seconds = [], 0.0
        with tempfile.TemporaryDirectory() as tmp:
            for seed in (FIRST_SEED, 1_000_033):
                image, header, _ = render(scene, Path(tmp) / "half.exr", resolution, spp=half, aov="beauty",
                                          **dict(settings, seed=seed))
                halves.append(image)
                seconds += header["lucerna/render_seconds"]
        image = (halves[0] + halves[1]) / 2
        noise = float(np.mean((halves[0] - halves[1]) ** 2 / (image ** 2 + 0.01))) / 4
        info = {"scene": str(scene), "resolution": list(resolution), "spp": 2 * half, "settings": settings,
                "seconds": seconds, "relmse_noise": noise, "commit": commit()}
        np.save(image_path, image)
        meta.write_text(json.dumps(info, indent=1))
    return np.load(image_path), json.loads(meta.read_text())


def commit():
    """The repository's commit (`git describe --always --dirty`), or "?" outside a clone."""
    done = subprocess.run(["git", "-C", str(ROOT), "describe", "--always", "--dirty"], capture_output=True,
                          text=True)
    return done.stdout.strip() if done.returncode == 0 else "?"


# Mesh attributes of a scene file: (key, floats or words per element, numpy type).
ATTRIBUTES = [("positions", 3, "<f4"), ("normals", 3, "<f4"), ("tangents", 4, "<f4"),
              ("uvs0", 2, "<f4"), ("uvs1", 2, "<f4"), ("colors", 4, "<f4"),
              ("triangles", 3, "<u4")]


class SceneFile:
    """A lucerna scene file in memory: the manifest, and each mesh's arrays decoded from
    the buffer (None where absent)."""

    def __init__(self, path):
        path = Path(path)
        self.manifest = json.loads(path.read_text())
        buffer = (path.parent / self.manifest["buffer"]).read_bytes()
        self.arrays = []
        for mesh in self.manifest["meshes"]:
            arrays = {}
            for key, width, dtype in ATTRIBUTES:
                view = self._view(mesh, key)
                arrays[key] = None if view is None else np.frombuffer(
                    buffer, dtype, view["count"] * width, view["offset"]).reshape(-1, width).copy()
            self.arrays.append(arrays)
        # Texel bytes of each texture (4 bytes a texel for rgba8, 16 for rgba32f).
        self.texels = []
        for t in self.manifest.get("textures", []):
            size = t["texels"]["count"] * (4 if t["encoding"] == "rgba8" else 16)
            self.texels.append(buffer[t["texels"]["offset"]:t["texels"]["offset"] + size])

    @staticmethod
    def _view(mesh, key):
        if key.startswith("uvs"):
            return mesh["uvs"][int(key[3])]
        return mesh[key]

    def write(self, path):
        path = Path(path)
        blob = bytearray()
        manifest = copy.deepcopy(self.manifest)
        for mesh, arrays in zip(manifest["meshes"], self.arrays):
            mesh["uvs"] = [None, None]
            for key, width, dtype in ATTRIBUTES:
                a = arrays.get(key)
                view = None
                if a is not None:
                    data = np.ascontiguousarray(a, dtype=dtype).tobytes()
                    view = {"offset": len(blob), "count": len(a)}
                    blob += data
                if key.startswith("uvs"):
                    mesh["uvs"][int(key[3])] = view
                else:
                    mesh[key] = view
        for texture, texels in zip(manifest.get("textures", []), self.texels):
            while len(blob) % 4:
                blob.append(0)
            texture["texels"] = {"offset": len(blob), "count": texture["texels"]["count"]}
            blob += texels
        manifest["buffer"] = path.name + ".bin"
        manifest["buffer_bytes"] = len(blob)
        (path.parent / manifest["buffer"]).write_bytes(bytes(blob))
        path.write_text(json.dumps(manifest))
        return path

    def add_mesh(self, name, positions, triangles, material, normals=None):
        self.manifest["meshes"].append({"name": name, "material": material})
        self.arrays.append({"positions": np.asarray(positions, "<f4").reshape(-1, 3),
                            "triangles": np.asarray(triangles, "<u4").reshape(-1, 3),
                            "normals": None if normals is None else np.asarray(normals, "<f4").reshape(-1, 3)})
        mesh = len(self.arrays) - 1
        self.manifest["instances"].append({"name": name, "mesh": mesh, "transform": identity()})
        return mesh

    def add_material(self, name, **fields):
        material = dict(self.manifest["materials"][0])
        material.update(name=name, **fields)
        self.manifest["materials"].append(material)
        return len(self.manifest["materials"]) - 1


def cpu():
    """The CPU as reports name it: (model name, logical cores, widest vector ISA). Mitsuba's
    llvm variant and Embree run 16 lanes with AVX-512 and 8 with AVX2; lucerna's packet
    kernel runs 8 (AVX2) on both."""
    import platform
    info = Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").exists() else ""
    field = lambda name: next((line.split(":", 1)[1].strip() for line in info.splitlines()
                               if line.startswith(name)), "")
    flags = field("flags").split()
    isa = "AVX-512" if "avx512f" in flags else "AVX2" if "avx2" in flags else "SSE"
    return field("model name") or platform.processor(), os.cpu_count(), isa


def identity():
    return [1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0]


def tonemap(image):
    """Clamp and sRGB-encode linear RGB to uint8."""
    x = np.clip(image, 0.0, 1.0)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return (srgb * 255 + 0.5).astype(np.uint8)


def pinhole_directions(width, height, vfov):
    """The (unnormalised) directions of the pixel centres' rays of a pinhole camera looking
    down -Z with +Y up and vertical field of view `vfov` (radians): shape (height, width, 3),
    row 0 at the top."""
    ys, xs = np.mgrid[0:height, 0:width]
    t = math.tan(vfov / 2)
    u = ((xs + 0.5) / width * 2 - 1) * t * width / height
    v = (1 - (ys + 0.5) / height * 2) * t
    return np.stack([u, v, -np.ones_like(u)], -1)


def difference_sheet(ours, theirs, path):
    """A PNG of three panels side by side: `ours` and `theirs` (linear RGB, Reinhard
    x / (1 + x) and gamma 2.2, so bright emitters keep their shape) and 4 x |ours - theirs|."""
    import OpenImageIO as oiio
    tone = lambda x: np.clip((np.maximum(x, 0) / (1 + np.maximum(x, 0))) ** (1 / 2.2), 0, 1)  # noqa: E731
    sheet = np.concatenate([tone(ours), tone(theirs), np.clip(4 * np.abs(ours - theirs), 0, 1)], axis=1)
    image = oiio.ImageBuf(oiio.ImageSpec(sheet.shape[1], sheet.shape[0], 3, oiio.UINT8))
    image.set_pixels(oiio.ROI(), sheet.astype(np.float32))
    image.write(str(path))


def grid_png(images, labels, path, columns=3, title=None):
    """A labelled grid of tone-mapped images."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rows = (len(images) + columns - 1) // columns
    h, w = images[0].shape[:2]
    scale = 4.0 / w
    fig, axes = plt.subplots(rows, columns, figsize=(columns * w * scale, rows * (h * scale + 0.45)), squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for ax, image, label in zip(axes.flat, images, labels):
        ax.imshow(tonemap(image), interpolation="nearest")
        ax.set_title(label, fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
