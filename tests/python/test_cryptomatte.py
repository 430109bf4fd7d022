"""Cryptomatte, decoded independently: this file implements MurmurHash3_32 and the
specification's id conversion and decoding (Psyop Cryptomatte 1.1) itself, reads lucerna's
EXR with OpenImageIO, and recovers each object's mask from the six ranks. Checked: the
header's keys, names, hash, conversion and manifest; coverage adding up to 1 in every pixel
(the pixel's alpha: 1 wherever all samples see the box); ranks ordered by coverage; and, where a
pixel sees one object only, that object against an independent reference: which wall the
pixel's position and normal (the data layers) lie on, and its material matte."""
import json
import os
import subprocess
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

ROOT = Path(__file__).resolve().parents[2]
LUCERNA = os.environ.get("LUCERNA_BIN", str(ROOT / "target/release/lucerna"))


def murmur3_32(data, seed=0):
    """MurmurHash3_x86_32, written from Austin Appleby's reference."""
    c1, c2, mask = 0xCC9E2D51, 0x1B873593, 0xFFFFFFFF
    rotl = lambda x, r: ((x << r) | (x >> (32 - r))) & mask  # noqa: E731
    h = seed
    n = len(data) // 4 * 4
    for i in range(0, n, 4):
        k = int.from_bytes(data[i:i + 4], "little")
        k = (rotl((k * c1) & mask, 15) * c2) & mask
        h = (rotl(h ^ k, 13) * 5 + 0xE6546B64) & mask
    k = int.from_bytes(data[n:] + b"\0" * (4 - len(data[n:])), "little") if len(data) > n else 0
    if len(data) > n:
        h ^= (rotl((k * c1) & mask, 15) * c2) & mask
    h ^= len(data)
    h ^= h >> 16
    h = (h * 0x85EBCA6B) & mask
    h ^= h >> 13
    h = (h * 0xC2B2AE35) & mask
    return h ^ (h >> 16)


def name_to_id(name):
    """The specification's id: the hash, with exponent 0 or 255 avoided by flipping bit 23."""
    h = murmur3_32(name.encode())
    if (h >> 23) & 0xFF in (0, 255):
        h ^= 1 << 23
    return h


def float_bits(plane):
    return np.frombuffer(np.ascontiguousarray(plane, dtype="<f4").tobytes(), dtype="<u4").reshape(plane.shape)


def decode(pixels, channels, type_name):
    """{id: coverage image} from the ranks of `type_name` (layers 00, 01, ...)."""
    masks = {}
    layer = 0
    while f"{type_name}{layer:02d}.R" in channels:
        for id_c, cov_c in (("R", "G"), ("B", "A")):
            ids = float_bits(pixels[..., channels.index(f"{type_name}{layer:02d}.{id_c}")])
            cov = pixels[..., channels.index(f"{type_name}{layer:02d}.{cov_c}")]
            for value in np.unique(ids[cov > 0]):
                masks.setdefault(int(value), np.zeros(cov.shape, np.float64))
                masks[int(value)] += np.where(ids == value, cov, 0.0)
        layer += 1
    return masks, layer


def test_hash_matches_the_reference_values():
    assert murmur3_32(b"") == 0
    assert murmur3_32(b"hello") == 0x248BFA47


def test_cryptomatte_layers_decode_to_the_objects(tmp_path):
    out = tmp_path / "crypto.exr"
    subprocess.run([LUCERNA, "render", "-q", "--resolution", "48x48", "--spp", "32",
                    "--aov", "crypto,normal,position", "-o", str(out)], check=True)
    image = oiio.ImageInput.open(str(out))
    spec = image.spec()
    pixels = image.read_image(format="float")
    image.close()
    channels = list(spec.channelnames)
    manifests = {}
    for type_name in ("CryptoObject", "CryptoMaterial"):
        key = f"{murmur3_32(type_name.encode()):08x}"[:7]
        attr = lambda field: spec.getattribute(f"cryptomatte/{key}/{field}")  # noqa: E731
        assert attr("name") == type_name
        assert attr("hash") == "MurmurHash3_32"
        assert attr("conversion") == "uint32_to_float32"
        manifest = json.loads(attr("manifest"))
        for name, hex_id in manifest.items():
            assert int(hex_id, 16) == name_to_id(name), name
        manifests[type_name] = {int(h, 16): n for n, h in manifest.items()}
    objects, layers = decode(pixels, channels, "CryptoObject")
    materials, _ = decode(pixels, channels, "CryptoMaterial")
    assert layers == 3  # six ranks
    # Coverage adds up to the pixel's alpha (the share of samples that hit a surface): 1
    # inside the box; at the image's edge, filter samples reach past the open box.
    alpha = pixels[..., channels.index("A")]
    assert np.mean(alpha == 1.0) > 0.9
    for masks in (objects, materials):
        total = sum(masks.values())
        assert np.all(np.abs(total - alpha) <= 1e-3), np.abs(total - alpha).max()
        assert np.all(np.abs(total[alpha == 1.0] - 1.0) <= 1e-3)
    assert set(objects) <= set(manifests["CryptoObject"])
    named = {manifests["CryptoObject"][i]: m for i, m in objects.items()}
    assert {"floor", "back_wall", "red_wall", "green_wall", "tall_block"} <= set(named)
    # Ranks come in decreasing coverage.
    covs = [pixels[..., channels.index(f"CryptoObject{k // 2:02d}.{'GA'[k % 2]}")] for k in range(6)]
    for a, b in zip(covs, covs[1:]):
        assert np.all(a >= b)
    # Independent reference: the surface a pixel's mean position and normal lie on.
    n = np.stack([pixels[..., channels.index(f"normal.{c}")] for c in "XYZ"], -1)
    p = np.stack([pixels[..., channels.index(f"position.{c}")] for c in "XYZ"], -1)
    lo, hi = p.reshape(-1, 3).min(0), p.reshape(-1, 3).max(0)
    near = lambda v, target: np.abs(v - target) < 2e-3 * (hi - lo).max()  # noqa: E731
    reference = {
        "floor": (n[..., 1] > 0.999) & near(p[..., 1], lo[1]),
        "back_wall": (np.abs(n[..., 2]) > 0.999) & (near(p[..., 2], lo[2]) | near(p[..., 2], hi[2])),
        "side_wall": (np.abs(n[..., 0]) > 0.999) & (near(p[..., 0], lo[0]) | near(p[..., 0], hi[0])),
    }
    checked = 0
    wall_material = {"red_wall": "red", "green_wall": "green", "floor": "white", "back_wall": "white"}
    for surface, where in reference.items():
        pure = where & (max_coverage(objects) >= 0.999)
        for y, x in zip(*np.nonzero(pure)):
            name = max(named, key=lambda k: named[k][y, x])
            expected = ("red_wall", "green_wall") if surface == "side_wall" else (surface,)
            assert name in expected, (surface, name, y, x)
            material = max(materials, key=lambda k: materials[k][y, x])
            assert manifests["CryptoMaterial"][material] == wall_material[name], (name, y, x)
            checked += 1
    assert checked > 200, checked


def max_coverage(masks):
    return np.max(np.stack(list(masks.values())), axis=0)
