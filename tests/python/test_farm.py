"""tools/farm: the Dask runner, on a local cluster of two workers, renders 2 frames x 4
tiles x 2 passes of the animated Cornell box, and every merged frame equals the render of
that frame by one process; the OpenCue export loads back with pyoutline as the same graph."""
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

ROOT = Path(__file__).resolve().parents[2]
FARM = ROOT / "tools/farm/farm.py"
SCENE = ROOT / "scenes/cornell-box/cornell-box-animated.gltf"
LUCERNA = os.environ.get("LUCERNA_BIN", str(ROOT / "target/release/lucerna"))
ARGS = ["--frames", "0,24", "--resolution", "40x36", "--tiles", "2x2", "--passes", "2",
        "--spp", "8", "--lucerna", LUCERNA]


def read(path):
    image = oiio.ImageInput.open(str(path))
    assert image is not None, oiio.geterror()
    spec = image.spec()
    pixels = image.read_image(format="float")
    image.close()
    return list(spec.channelnames), pixels


def test_local_cluster_renders_frames_equal_to_single_process_renders(tmp_path):
    proc = subprocess.run([sys.executable, str(FARM), "run", str(SCENE), *ARGS, "--workers",
                           "2", "-o", str(tmp_path / "farm/{scene}.{frame}.exr"),
                           "--report", str(tmp_path / "report.json")],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "18 of 18 tasks done" in proc.stdout, proc.stdout
    for frame in (0, 24):
        single = tmp_path / f"single.{frame}.exr"
        subprocess.run([LUCERNA, "render", "-q", str(SCENE), "--frame", str(frame),
                        "--resolution", "40x36", "--spp", "8", "-o", str(single)], check=True)
        names, expected = read(single)
        merged_names, merged = read(tmp_path / f"farm/cornell-box-animated.{frame:04d}.exr")
        # The single render writes the beauty; the merge of passes also keeps their spp.
        assert set(names) <= set(merged_names), (names, merged_names)
        merged = merged[..., [merged_names.index(n) for n in names]]
        # Passes merge up to float rounding (sums re-formed from f32 means).
        np.testing.assert_allclose(merged, expected, rtol=1e-5, atol=1e-7)
    # The two frames differ: the camera moved.
    assert not np.allclose(read(tmp_path / "farm/cornell-box-animated.0000.exr")[1],
                           read(tmp_path / "farm/cornell-box-animated.0024.exr")[1])


def test_opencue_export_loads_back_with_pyoutline(tmp_path):
    path = tmp_path / "job.outline"
    proc = subprocess.run([sys.executable, str(FARM), "opencue", str(SCENE), *ARGS,
                           "-o", str(tmp_path / "{scene}.{frame}.exr"), "--outline", str(path)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    import outline
    from outline import cuerun
    job = outline.load_outline(str(path))
    layers = {layer.get_name(): layer for layer in job.get_layers()}
    renders = [n for n in layers if n.startswith("render-")]
    assert sorted(renders) == sorted(f"render-t{t}-p{k}" for t in range(4) for k in (1, 2))
    for name in renders:
        command = layers[name].get_arg("command")
        assert command[:2] == [LUCERNA, "render"]
        assert command[command.index("--frame") + 1] == "%{FRAME}"
        assert "%{ZFRAME}" in command[command.index("-o") + 1]
        assert layers[name].get_frame_range() == "0,24"
    merge = layers["merge"]
    assert merge.get_arg("command")[1] == "merge"
    depends = {(d.get_depend_on_layer().get_name(), d.get_type()) for d in merge.get_depends()}
    assert depends == {(n, "FRAME_BY_FRAME") for n in renders}
    # The job specification Cuebot takes: 9 layers, 8 frame-by-frame dependencies.
    spec = cuerun.OutlineLauncher(job, range="0,24").serialize(use_pycuerun=False)
    assert spec.count("<layer ") == 9 and spec.count('type="FRAME_BY_FRAME"') == 8, spec
