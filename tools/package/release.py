#!/usr/bin/env python3
"""A prebuilt release of lucerna: one tarball with the binary (the USD plugin is embedded in
it), its man pages and shell completions, the README, CHANGELOG and licences, and a SHA-256
checksum file beside it, as the peers ship their command-line renderers:

    .venv/bin/python tools/package/release.py [--binary target/release/lucerna] [--out target/release-dist]

writes OUT/lucerna-VERSION-TARGET.tar.gz (one folder lucerna-VERSION-TARGET/: bin/lucerna,
share/man/man1/, share/bash-completion/completions/lucerna, share/zsh/site-functions/_lucerna,
share/fish/vendor_completions.d/lucerna.fish, README.md, CHANGELOG.md, LICENSE-MIT,
LICENSE-APACHE) and OUT/lucerna-VERSION-TARGET.tar.gz.sha256 (`sha256sum -c` reads it). The
archive is reproducible: its entries are sorted, owned by root and dated SOURCE_DATE_EPOCH
(0 without it). Unpack it anywhere and put its bin/ on PATH; USD stages need a Python with
usd-core (`lucerna setup` makes one)."""
import argparse
import gzip
import hashlib
import io
import os
import platform
import shutil
import subprocess
import sys
import tarfile
import tempfile
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
COMPLETIONS = {"bash": "share/bash-completion/completions/lucerna", "zsh": "share/zsh/site-functions/_lucerna",
               "fish": "share/fish/vendor_completions.d/lucerna.fish"}
FILES = ["README.md", "CHANGELOG.md", "LICENSE-MIT", "LICENSE-APACHE"]


def target():
    """The Rust target triple of this machine (the binary's)."""
    try:
        host = subprocess.run(["rustc", "-vV"], capture_output=True, text=True, check=True).stdout
        return next(line.split()[1] for line in host.splitlines() if line.startswith("host:"))
    except (OSError, subprocess.CalledProcessError, StopIteration):
        return f"{platform.machine()}-unknown-linux-gnu"


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--binary", default=str(ROOT / "target" / "release" / "lucerna"))
    parser.add_argument("--out", default=str(ROOT / "target" / "release-dist"))
    args = parser.parse_args()
    binary = Path(args.binary)
    if not binary.is_file():
        sys.exit(f"no binary at {binary} (cargo build --release --locked)")
    version = tomllib.loads((ROOT / "Cargo.toml").read_text())["package"]["version"]
    name = f"lucerna-{version}-{target()}"
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        stage = Path(tmp) / name
        (stage / "bin").mkdir(parents=True)
        shutil.copy2(binary, stage / "bin" / "lucerna")
        man = stage / "share" / "man" / "man1"
        man.mkdir(parents=True)
        subprocess.run([str(binary), "man", str(man)], check=True, capture_output=True)
        for shell, path in COMPLETIONS.items():
            (stage / path).parent.mkdir(parents=True, exist_ok=True)
            script = subprocess.run([str(binary), "completions", shell], check=True, capture_output=True).stdout
            (stage / path).write_bytes(script)
        for f in FILES:
            shutil.copy2(ROOT / f, stage / f)
        epoch = int(os.environ.get("SOURCE_DATE_EPOCH", "0"))
        raw = io.BytesIO()
        with tarfile.open(fileobj=raw, mode="w", format=tarfile.PAX_FORMAT) as tar:
            for path in sorted([stage, *stage.rglob("*")]):
                info = tar.gettarinfo(str(path), arcname=str(path.relative_to(Path(tmp))))
                info.uid = info.gid = 0
                info.uname = info.gname = "root"
                info.mtime = epoch
                if info.isfile():
                    info.mode = 0o755 if os.access(path, os.X_OK) else 0o644
                    with open(path, "rb") as f:
                        tar.addfile(info, f)
                else:
                    info.mode = 0o755
                    tar.addfile(info)
    archive = out / f"{name}.tar.gz"
    with open(archive, "wb") as f, gzip.GzipFile(fileobj=f, mode="wb", mtime=epoch, filename="") as gz:
        gz.write(raw.getvalue())
    digest = hashlib.sha256(archive.read_bytes()).hexdigest()
    (out / f"{archive.name}.sha256").write_text(f"{digest}  {archive.name}\n")
    print(f"wrote {archive} ({archive.stat().st_size} bytes), sha256 {digest}")


if __name__ == "__main__":
    main()
