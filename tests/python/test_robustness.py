"""Robustness of the command line (issue 43): signals at any time, memory checked before
decoding, outputs and inputs that are not plain files, names OpenEXR cannot hold, numbers
that would overflow, merges and batches that must not trust what they read."""
import json
import os
import signal
import subprocess
import time
import zlib
import struct
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

ROOT = Path(__file__).resolve().parents[2]
LUCERNA = os.environ.get("LUCERNA_BIN", str(ROOT / "target/release/lucerna"))
CORNELL = ROOT / "scenes/cornell-box/cornell-box.gltf"
USD_TWIN = ROOT / "scenes/usd-twin/usd-twin.usda"


def run(*args, **kwargs):
    return subprocess.run([LUCERNA, *map(str, args)], capture_output=True, text=True,
                          timeout=kwargs.pop("timeout", 120), **kwargs)


def read_exr(path):
    image = oiio.ImageInput.open(str(path))
    assert image is not None, oiio.geterror()
    spec = image.spec()
    pixels = image.read_image(format="float")
    image.close()
    return spec, pixels


def png_declaring(width, height):
    def chunk(kind, data):
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 6, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"\0" * 64)) + chunk(b"IEND", b""))


def wait_for_progress(proc):
    """Reads the render's stderr up to its first progress line (the render is sampling)."""
    for line in proc.stderr:
        if "progress" in line:
            return
    raise AssertionError("the render ended without a progress line")


def processes_mentioning(text):
    """Pids whose command line contains `text` (read from /proc: no procps needed)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if text.encode() in (entry / "cmdline").read_bytes():
                    found.append(int(entry.name))
            except OSError:
                pass
    return found


# 1. Interruption


def test_a_signal_while_a_usd_stage_converts_ends_the_process_at_once(tmp_path):
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    out = tmp_path / "out.exr"
    env = dict(os.environ, TMPDIR=str(scratch))
    proc = subprocess.Popen([LUCERNA, "render", str(USD_TWIN), "-o", str(out), "--spp", "4"],
                            stderr=subprocess.PIPE, text=True, env=env)
    # The signal goes as soon as the plugin runs: Python and usd-core take far longer to
    # start than this loop takes to see it.
    deadline = time.monotonic() + 10
    while not processes_mentioning(str(scratch)) and time.monotonic() < deadline:
        time.sleep(0.002)
    sent = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    _, stderr = proc.communicate(timeout=10)
    took = time.monotonic() - sent
    assert proc.returncode == 128 + signal.SIGTERM, stderr
    assert "before any result; nothing written" in stderr, stderr
    assert took < 1.0, f"{took:.2f} s to stop"
    assert not out.exists()
    time.sleep(0.2)
    assert list(scratch.iterdir()) == [], "the plugin's scratch folder is left behind"
    assert not processes_mentioning(str(scratch)), "the plugin still runs"


def test_a_checkpoint_resumes_by_another_path_and_keeps_a_unicode_name(tmp_path):
    folder = tmp_path / "szene-日本"
    folder.mkdir()
    scene = folder / "küche.gltf"
    scene.write_bytes(CORNELL.read_bytes())
    out = tmp_path / "out.exr"
    common = ["--spp", "3000", "--resolution", "32x32", "--aov", "beauty"]
    lines = ["--progress", "lines", "--progress-interval", "0.05"]
    proc = subprocess.Popen([LUCERNA, "render", str(scene), "-o", str(out), *common, *lines],
                            stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    wait_for_progress(proc)
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=10)
    assert proc.returncode == 128 + signal.SIGINT, stderr
    spec, _ = read_exr(out)
    assert spec.getattribute("lucerna/scene") == str(scene)
    assert spec.getattribute("lucerna/complete") == 0
    other_spelling = Path("szene-日本") / ".." / "szene-日本" / "küche.gltf"
    resumed = run("render", other_spelling, "-o", out, *common, "--resume", cwd=tmp_path)
    assert resumed.returncode == 0 and "continuing" in resumed.stderr, resumed.stderr
    spec, pixels = read_exr(out)
    assert spec.getattribute("lucerna/complete") == 1 and np.isfinite(pixels).all()
    # The same path with other content is not the same scene.
    proc = subprocess.Popen([LUCERNA, "render", str(scene), "-o", str(out), *common, *lines],
                            stderr=subprocess.PIPE, text=True)
    wait_for_progress(proc)
    proc.send_signal(signal.SIGTERM)
    proc.communicate(timeout=10)
    scene.write_bytes(CORNELL.read_bytes() + b"\n")
    refused = run("render", scene, "-o", out, *common, "--resume")
    assert refused.returncode == 2 and "has changed" in refused.stderr, refused.stderr


# 2. Memory before allocation


def test_an_image_header_is_checked_against_the_memory_limit_before_decoding(tmp_path):
    png = tmp_path / "huge.png"
    png.write_bytes(png_declaring(16000, 16000))  # 256 Mpixel: 2 GiB to decode
    start = time.monotonic()
    result = run("render", "-o", tmp_path / "o.exr", "--env-map", png, "--max-memory", "512M",
                 "--spp", "1", "--resolution", "8x8")
    assert result.returncode == 2, result.stderr
    assert "--max-memory" in result.stderr and "16000x16000" in result.stderr, result.stderr
    assert time.monotonic() - start < 5


# 3. Outputs and inputs


@pytest.mark.parametrize("kind", ["device", "directory", "fifo"])
def test_outputs_that_are_not_files_are_refused_before_rendering(tmp_path, kind):
    target = {"device": Path("/dev/null"), "directory": tmp_path / "d.exr",
              "fifo": tmp_path / "f.exr"}[kind]
    if kind == "fifo":
        os.mkfifo(target)
    elif kind == "directory":
        target.mkdir()
    result = run("render", "-o", target, "--spp", "1", "--resolution", "8x8", timeout=20)
    assert result.returncode == 2, result.stderr
    # /dev/null is refused for its name (not .exr) before its kind is looked at.
    refusal = "not an .exr file" if kind == "device" else "never replaced"
    assert refusal in result.stderr and "rendered" not in result.stderr, result.stderr
    assert Path("/dev/null").is_char_device()


def test_an_input_fifo_is_refused_instead_of_blocking(tmp_path):
    fifo = tmp_path / "scene.gltf"
    os.mkfifo(fifo)
    result = run("render", fifo, "-o", tmp_path / "o.exr", timeout=20)
    assert result.returncode == 2 and "FIFO" in result.stderr, result.stderr


def test_a_symlink_out_of_the_scene_directory_is_refused(tmp_path):
    scene_dir = tmp_path / "scene"
    scene_dir.mkdir()
    doc = json.loads(CORNELL.read_text())
    outside = tmp_path / "secret.bin"
    buffer = doc["buffers"][0]
    import base64
    outside.write_bytes(base64.b64decode(buffer["uri"].split(",", 1)[1]))
    (scene_dir / "data.bin").symlink_to(outside)
    buffer["uri"] = "data.bin"
    (scene_dir / "s.gltf").write_text(json.dumps(doc))
    result = run("render", scene_dir / "s.gltf", "-o", tmp_path / "o.exr", "--spp", "1")
    assert result.returncode == 2 and "symbolic link" in result.stderr, result.stderr


def test_a_camera_name_cannot_lead_the_output_out_of_its_directory(tmp_path):
    doc = json.loads(CORNELL.read_text())
    doc["cameras"][0]["name"] = "../../escaped"
    scene = tmp_path / "s.gltf"
    scene.write_text(json.dumps(doc))
    (tmp_path / "out").mkdir()
    result = run("render", scene, "-o", tmp_path / "out/{camera}.exr", "--spp", "1",
                 "--resolution", "8x8")
    assert result.returncode == 0, result.stderr
    assert [p.name for p in (tmp_path / "out").iterdir()] == ["__.._escaped.exr"]


# 4. Written files are valid


def test_a_light_group_name_too_long_for_openexr_is_refused_before_rendering(tmp_path):
    out = tmp_path / "o.exr"
    result = run("render", "-o", out, "--spp", "1", "--resolution", "8x8", "--aov",
                 "lightgroups", "--light-group", "a" * 300 + "=*")
    assert result.returncode == 2 and "channel name" in result.stderr, result.stderr
    assert not out.exists()


def test_batch_refuses_two_renders_of_one_output_and_rerenders_changed_settings(tmp_path):
    job = tmp_path / "job.toml"
    job.write_text('[[render]]\noutput = "out/a.exr"\nresolution = "8x8"\n'
                   'settings = { spp = 2 }\n'
                   '[[render]]\noutput = "out/../out/a.exr"\nresolution = "8x8"\n')
    result = run("batch", job)
    assert result.returncode == 2 and "two renders cannot write one file" in result.stderr
    job.write_text('[[render]]\noutput = "out/a.exr"\nresolution = "8x8"\n'
                   'settings = { spp = 2 }\n')
    assert run("batch", job).returncode == 0
    summary = json.loads((tmp_path / "job.summary.json").read_text())
    assert summary["rendered"] == 1
    assert run("batch", job).returncode == 0
    summary = json.loads((tmp_path / "job.summary.json").read_text())
    assert summary["skipped"] == 1, summary
    job.write_text(job.read_text().replace("spp = 2", "spp = 3"))
    result = run("batch", job)
    summary = json.loads((tmp_path / "job.summary.json").read_text())
    assert summary["rendered"] == 1, summary
    assert "samples per pixel" in summary["frames"][0]["note"], summary
    # A complete-looking file that does not read back whole is rendered again.
    exr = tmp_path / "out/a.exr"
    exr.write_bytes(exr.read_bytes()[:-100])
    run("batch", job)
    summary = json.loads((tmp_path / "job.summary.json").read_text())
    assert summary["rendered"] == 1 and "unreadable" in summary["frames"][0]["note"], summary


# 5. Honest numbers


@pytest.mark.parametrize("args", [["--env", "3e38"], ["--frame", "nan"], ["--frame", "inf"]])
def test_values_beyond_range_are_refused(tmp_path, args):
    result = run("render", "-o", tmp_path / "o.exr", "--spp", "1", *args)
    assert result.returncode == 2, result.stderr
    assert "panicked" not in result.stderr


def test_a_very_bright_emitter_gives_finite_layers(tmp_path):
    doc = json.loads(CORNELL.read_text())
    for material in doc["materials"]:
        if any(material.get("emissiveFactor", [0, 0, 0])):
            material["emissiveFactor"] = [1, 1, 1]
            material.setdefault("extensions", {})["KHR_materials_emissive_strength"] = {
                "emissiveStrength": 1e30}
    doc.setdefault("extensionsUsed", []).append("KHR_materials_emissive_strength")
    scene = tmp_path / "bright.gltf"
    scene.write_text(json.dumps(doc))
    out = tmp_path / "o.exr"
    result = run("render", scene, "-o", out, "--spp", "4", "--resolution", "16x16", "--aov",
                 "all")
    assert result.returncode == 0, result.stderr
    _, pixels = read_exr(out)
    assert np.isfinite(pixels).all()


def test_merge_refuses_non_finite_values_and_variance_without_beauty(tmp_path):
    parts = []
    for k in (1, 2):
        part = tmp_path / f"p{k}.exr"
        assert run("render", "-o", part, "--spp", "4", "--pass", f"{k}/2", "--resolution",
                   "8x8", "--aov", "variance,spp").returncode == 0
        parts.append(part)
    buf = oiio.ImageBuf(str(parts[1]))
    pixels = buf.get_pixels(oiio.FLOAT)
    pixels[0, 0, 0] = np.nan
    buf.set_pixels(buf.roi, pixels)
    bad = tmp_path / "nan.exr"
    assert buf.write(str(bad)), buf.geterror()
    result = run("merge", parts[0], bad, "-o", tmp_path / "m.exr")
    assert result.returncode == 2 and "must be finite" in result.stderr, result.stderr
    names = list(oiio.ImageBuf(str(parts[1])).spec().channelnames)
    keep = [i for i, n in enumerate(names) if n not in ("R", "G", "B", "A")]
    novar = oiio.ImageBufAlgo.channels(oiio.ImageBuf(str(parts[1])), tuple(keep))
    without_beauty = tmp_path / "nobeauty.exr"
    assert novar.write(str(without_beauty)), novar.geterror()
    for inputs in ([without_beauty, without_beauty], [parts[0], without_beauty]):
        result = run("merge", *inputs, "-o", tmp_path / "m.exr")
        assert result.returncode == 2 and "panicked" not in result.stderr, result.stderr


def test_a_hung_usd_plugin_is_stopped_after_the_timeout(tmp_path):
    fake = tmp_path / "python"
    fake.write_text(f"#!/bin/sh\nexec sleep 60 # {tmp_path}\n")
    fake.chmod(0o755)
    env = dict(os.environ, LUCERNA_PYTHON=str(fake), TMPDIR=str(tmp_path))
    start = time.monotonic()
    result = run("render", USD_TWIN, "-o", tmp_path / "o.exr", "--usd-timeout", "1", env=env)
    assert result.returncode == 1 and "still converting after 1 s" in result.stderr, result.stderr
    assert time.monotonic() - start < 5
    assert not list(tmp_path.glob("lucerna-usd-*"))


# 6. Round 3: USD errors name the stage and the prim; no stale files; small acceptances


def light_stage(tmp_path, name, attribute):
    stage = tmp_path / f"{name}.usda"
    stage.write_text(f"""#usda 1.0
(
    upAxis = "Y"
)

def Mesh "Floor"
{{
    point3f[] points = [(-1,0,-1),(1,0,-1),(1,0,1),(-1,0,1)]
    int[] faceVertexCounts = [4]
    int[] faceVertexIndices = [0,3,2,1]
}}

def SphereLight "Key"
{{
    {attribute}
    float inputs:radius = 0.1
    double3 xformOp:translate = (0, 1, 0)
    uniform token[] xformOpOrder = ["xformOp:translate"]
}}
""")
    return stage


@pytest.mark.parametrize("name,attribute,reason", [
    ("nan", "float inputs:intensity = nan", "inputs:intensity is nan"),
    ("inf", "float inputs:intensity = inf", "inputs:intensity is inf"),
    ("negative", "float inputs:intensity = -5", "inputs:intensity is -5"),
    ("overflow", "float inputs:exposure = 200", "more than 1e+18"),
    ("colour", "color3f inputs:color = (1, -1, 0)", "inputs:color is"),
])
def test_a_light_the_renderer_cannot_hold_is_refused_naming_stage_and_prim(tmp_path, name, attribute,
                                                                           reason):
    stage = light_stage(tmp_path, name, attribute)
    result = run("render", stage, "-o", tmp_path / "o.exr", "--spp", "1", "--resolution", "8x8")
    assert result.returncode == 2, result.stderr
    last = result.stderr.strip().splitlines()[-1]
    assert last.startswith(f"error: {stage}: /Key: ") and reason in last, last
    assert "lucerna-usd-" not in last and "Traceback" not in result.stderr, result.stderr
    assert not (tmp_path / "o.exr").exists()


def fake_plugin(tmp_path, main):
    """A plugin folder whose `convert` runs `main` (Python source) instead."""
    package = tmp_path / "plugin" / "lucerna_usd"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "__main__.py").write_text(main)
    (package.parent / "requirements.txt").write_text("")
    return package.parent


def test_a_plugin_that_writes_nothing_is_reported_against_the_stage(tmp_path):
    plugin = fake_plugin(tmp_path, "import sys\nsys.exit(0)\n")
    env = dict(os.environ, LUCERNA_USD_PLUGIN=str(plugin))
    result = run("render", USD_TWIN, "-o", tmp_path / "o.exr", env=env)
    assert result.returncode == 1, result.stderr
    last = result.stderr.strip().splitlines()[-1]
    assert last.startswith(f"error: {USD_TWIN}: usd plugin: ") and "wrote no scene file" in last, last


def test_a_silent_plugin_is_stopped_when_it_shows_no_progress(tmp_path):
    plugin = fake_plugin(tmp_path, "import time\ntime.sleep(60)\n")
    env = dict(os.environ, LUCERNA_USD_PLUGIN=str(plugin), LUCERNA_USD_STALL_SECONDS="1",
               TMPDIR=str(tmp_path))
    start = time.monotonic()
    result = run("render", USD_TWIN, "-o", tmp_path / "o.exr", env=env)
    assert result.returncode == 1 and "no sign of progress" in result.stderr, result.stderr
    assert time.monotonic() - start < 10
    assert not list(tmp_path.glob("lucerna-usd-*"))


def test_a_beating_plugin_is_not_stopped_for_silence(tmp_path):
    # Heartbeats every 0.2 s for 2 s, then a clean refusal: the stall limit of 1 s never
    # fires, and the plugin's own error comes through.
    plugin = fake_plugin(tmp_path, """import sys, time
for _ in range(10):
    print("lucerna-usd: heartbeat", file=sys.stderr, flush=True)
    time.sleep(0.2)
print(f"lucerna-usd: error: {sys.argv[2]}: /World: done beating", file=sys.stderr)
sys.exit(2)
""")
    env = dict(os.environ, LUCERNA_USD_PLUGIN=str(plugin), LUCERNA_USD_STALL_SECONDS="1")
    result = run("render", USD_TWIN, "-o", tmp_path / "o.exr", env=env)
    assert result.returncode == 2 and "/World: done beating" in result.stderr, result.stderr
    assert "heartbeat" not in result.stderr, result.stderr


def test_stale_temporary_files_and_scratch_folders_are_removed(tmp_path):
    out = tmp_path / "frame.exr"
    dead = 2**22 + 12345  # beyond pid_max's default: no such process
    while Path(f"/proc/{dead}").exists():
        dead += 1
    stale = tmp_path / f".frame.exr.tmp-{dead}"
    stale.write_bytes(b"half a file")
    alive = tmp_path / f".frame.exr.tmp-{os.getpid()}"
    alive.write_bytes(b"another writer's")
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    left = scratch / f"lucerna-usd-p{dead}-abcdef"
    left.mkdir()
    (left / "scene.lucerna").write_text("{}")
    env = dict(os.environ, TMPDIR=str(scratch))
    result = run("render", USD_TWIN, "-o", out, "--spp", "1", "--resolution", "16x16", env=env)
    assert result.returncode == 0, result.stderr
    assert out.exists() and not stale.exists() and alive.exists()
    assert not left.exists(), list(scratch.iterdir())
    assert f"left by process {dead}, which is gone" in result.stderr, result.stderr


def test_an_environment_map_with_nan_texels_renders_finite_and_says_so(tmp_path):
    sky = tmp_path / "sky.exr"
    pixels = np.full((8, 16, 3), 0.5, dtype=np.float32)
    pixels[2, 3] = np.nan
    pixels[4, 5, 1] = np.inf
    pixels[6, 7, 2] = -1.0
    out = oiio.ImageOutput.create(str(sky))
    assert out.open(str(sky), oiio.ImageSpec(16, 8, 3, oiio.FLOAT)), oiio.geterror()
    out.write_image(pixels)
    out.close()
    result = run("render", "-o", tmp_path / "o.exr", "--env-map", sky, "--spp", "4",
                 "--resolution", "16x16")
    assert result.returncode == 0, result.stderr
    assert "3 of 128 texels are NaN, infinite or negative: rendered as black" in result.stderr, \
        result.stderr
    _, image = read_exr(tmp_path / "o.exr")
    assert np.isfinite(image).all()
