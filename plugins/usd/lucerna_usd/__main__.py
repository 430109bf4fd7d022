"""Command line of the USD plugin, the protocol lucerna's renderer speaks:

    python -m lucerna_usd convert STAGE -o OUT.lucerna [--frame F] [--no-validate | --strict]
    python -m lucerna_usd validate STAGE

`convert` opens STAGE (.usd, .usda, .usdc, .usdz), validates it with every registered
`pxr.UsdValidation` validator, converts the composed stage at time code F (default: the
stage's start time code if it has one, else the earliest time sample) and writes the scene
file OUT.lucerna and its buffer OUT.lucerna.bin. As husk and usdview do, it renders what
composes: validator findings (errors included) are warnings naming the prim and the
validator, missing stage metadata takes USD's fallbacks (Y up, centimetres, no default
prim), and a prim whose data cannot be converted is skipped with a warning naming it.
--strict stops on any validator error instead; --no-validate skips the validators. All
warnings go into the scene file's `warnings`, which the renderer prints. A stage is refused
only when it cannot be opened or nothing renderable remains. Problems are printed on stderr, one per line, as
`lucerna-usd: error: FILE: ELEMENT: REASON`.

Exit status: 0 converted; 2 the stage is bad (unreadable, failed validation, nothing to
convert); 3 a Python package is missing (the message names the install command); 1 an
internal failure (LUCERNA_USD_DEBUG=1 shows its traceback)."""

import argparse
import contextlib
import os
import sys
import tempfile
import time as clock

EXIT_BAD_INPUT = 2
EXIT_MISSING_PACKAGE = 3
REQUIREMENTS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                            "requirements.txt")


def _error(file, element, reason):
    reason = " ".join(str(reason).split())
    print(f"lucerna-usd: error: {file}: {element}: {reason}", file=sys.stderr)


@contextlib.contextmanager
def _captured_stderr(sink):
    """Collects what usd-core prints on the C-level stderr (its Tf diagnostics) into
    `sink` instead of the terminal; the plugin reports the same problems itself."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile(mode="w+b") as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            sink.append(tmp.read().decode(errors="replace"))


def _open(path, payloads=True):
    from pxr import Tf, Usd

    from . import heartbeat

    heartbeat()
    if not os.path.isfile(path):
        return None, "no such file"
    captured = []
    try:
        with _captured_stderr(captured):
            stage = Usd.Stage.Open(path, Usd.Stage.LoadAll if payloads else Usd.Stage.LoadNone)
    except Tf.ErrorException as e:
        return None, _tf_reason(e)
    if stage is None:
        return None, "usd-core cannot open the file"
    return stage, None


def select_variants(stage, selections, warn):
    """Applies `selections` ("SET=NAME": in every prim that has variant set SET, or
    "/Prim/Path:SET=NAME": in that prim) on the stage's session layer, so the files are
    unchanged; selections that bring in further variant sets are applied to those too."""
    from pxr import Sdf, Usd

    parsed = []
    for text in selections:
        where, _, choice = text.rpartition(":") if text.startswith("/") else ("", "", text)
        vset, sep, name = choice.partition("=")
        if not sep or not vset or not name:
            raise ValueError(f"--variant {text!r}: expected SET=NAME or /PRIM:SET=NAME")
        parsed.append((where, vset, name))
    applied = set()
    with Usd.EditContext(stage, stage.GetSessionLayer()):
        for _ in range(8):  # a selection may reveal prims with further variant sets
            changed = False
            for where, vset, name in parsed:
                prims = ([stage.GetPrimAtPath(Sdf.Path(where))] if where
                         else stage.Traverse(Usd.TraverseInstanceProxies(Usd.PrimAllPrimsPredicate)))
                for prim in prims:
                    if not prim or not prim.IsValid():
                        continue
                    sets = prim.GetVariantSets()
                    if not sets.HasVariantSet(vset):
                        continue
                    variant_set = sets.GetVariantSet(vset)
                    key = (str(prim.GetPath()), vset)
                    if name not in variant_set.GetVariantNames():
                        if key not in applied:
                            warn(str(prim.GetPath()), f"--variant {vset}={name}: no such variant "
                                 f"(it has {', '.join(variant_set.GetVariantNames())})")
                            applied.add(key)
                        continue
                    if variant_set.GetVariantSelection() != name:
                        variant_set.SetVariantSelection(name)
                        changed = True
                    applied.add(key)
            if not changed:
                break
    for where, vset, name in parsed:
        if not any(k[1] == vset and (not where or k[0] == where) for k in applied):
            warn(where or "stage", f"--variant {vset}={name}: no prim has the variant set {vset!r}")


def _shutter(text):
    """argparse's type of --shutter."""
    from .motion import parse

    try:
        return parse(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _time(stage, frame):
    from pxr import Usd

    if frame is not None:
        return Usd.TimeCode(frame)
    if stage.HasAuthoredTimeCodeRange():
        return Usd.TimeCode(stage.GetStartTimeCode())
    return Usd.TimeCode.EarliestTime()


def _validate(stage, path, strict, warnings):
    """Runs the validators; their findings become warnings. Returns False (after printing
    the errors) if `strict` and a validator reported an error."""
    from .validate import validate

    captured = []
    with _captured_stderr(captured):
        findings = validate(stage)
    errors = [f for f in findings if f.severity == "error"]
    if errors and strict:
        for f in errors:
            _error(path, ", ".join(f.sites) or "stage", f"{f.message} [{f.validator}]")
        print(f"lucerna-usd: {len(errors)} validation error(s) (--strict)", file=sys.stderr)
        return False
    for f in findings:
        warnings.append(f"validation {f.severity}: {f}")
    return True


def convert(path, output, frame=None, no_validate=False, quiet=False, strict=False,
            variants=(), purposes=("render",), payloads=True, render_settings=None, shutter=None,
            vectors=False):
    """Converts `path` to the scene file `output`; returns the exit status."""
    from pxr import Tf

    try:
        return _convert(path, output, frame, no_validate, quiet, strict, variants, purposes,
                        payloads, render_settings, shutter, vectors)
    except Tf.ErrorException as e:
        # usd-core raises on layers it cannot parse when composition reaches them.
        _error(path, "stage", _tf_reason(e))
        return EXIT_BAD_INPUT


def _tf_reason(error):
    messages = [line.strip() for line in str(error).splitlines() if line.strip()]
    detail = next((m.split(" : ", 1)[1] for m in messages if " : " in m), "; ".join(messages))
    return detail.strip("'")


def _convert(path, output, frame, no_validate, quiet, strict, variants=(), purposes=("render",),
             payloads=True, render_settings=None, shutter=None, vectors=False):
    from . import StageError
    from .convert import Converter

    started = clock.monotonic()
    stage, reason = _open(path, payloads)
    if stage is None:
        _error(path, "stage", reason)
        return EXIT_BAD_INPUT
    warnings = []
    if variants:
        try:
            select_variants(stage, variants, lambda element, text: warnings.append(f"{element}: {text}"))
        except ValueError as e:
            _error(path, "--variant", str(e))
            return EXIT_BAD_INPUT
    if not payloads:
        warnings.append("stage: payloads not loaded (--no-payloads)")
    from .mtlx import substitute_documents

    captured = []
    with _captured_stderr(captured):
        # The in-memory layers of referenced .mtlx documents live as long as the stage.
        stage_layers = substitute_documents(stage, lambda element, text: warnings.append(f"{element}: {text}"))
    if not no_validate and not _validate(stage, path, strict, warnings):
        return EXIT_BAD_INPUT
    if no_validate:
        for e in stage.GetCompositionErrors():
            text = e.GetErrorAsString() if hasattr(e, "GetErrorAsString") else str(e)
            warnings.append(f"composition: {' '.join(text.split())}")
    captured = []
    from . import render_settings as usd_render

    try:
        with _captured_stderr(captured):
            time = _time(stage, frame)
            from . import motion

            open_close = motion.shutter(stage, render_settings, shutter)
            blur = open_close is not None
            if open_close is None and vectors:
                open_close = motion.VECTOR_INTERVAL
            shutter_times = motion.times(time, open_close)
            converter = Converter(stage, path, time, purposes, shutter_times)
            writer = converter.run()
            if shutter_times:
                writer.shutter = {"open": open_close[0], "close": open_close[1]}
                if not blur:
                    writer.shutter["blur"] = False
            # Frame tokens of product names: the frame rendered, else the stage's start, else 1
            # (husk's default frame).
            number = frame if frame is not None else (
                stage.GetStartTimeCode() if stage.HasAuthoredTimeCodeRange() else 1.0)
            usd_render.convert(stage, writer, time, number, render_settings, converter.warn)
        del stage_layers  # the stage is no longer read
    except StageError as e:
        _error(path, e.element, e.reason)
        return EXIT_BAD_INPUT
    except ValueError as e:  # an explicit --render-settings that names no settings prim
        _error(path, "--render-settings", str(e))
        return EXIT_BAD_INPUT
    writer.warnings[:0] = warnings
    for text in captured:
        for line in text.splitlines():
            if line.strip():
                writer.warnings.append(f"usd-core: {line.strip()}")
    if not (writer.instances or writer.spheres or writer.disks or writer.cylinders or writer.lights
            or writer.volumes or writer.environment is not None):
        # What explains it (validator findings, skipped prims) comes first.
        for text in writer.warnings[:20]:
            print(f"lucerna-usd: warning: {text}", file=sys.stderr)
        _error(path, "stage", "nothing to render (no meshes, spheres, volumes or lights)")
        return EXIT_BAD_INPUT
    try:
        writer.write(output)
    except StageError as e:
        _error(path, e.element, e.reason)
        return EXIT_BAD_INPUT
    if not quiet:
        print(f"lucerna-usd: {path} -> {output}: {len(writer.meshes)} meshes, "
              f"{len(writer.instances)} instances, {len(writer.materials)} materials, "
              f"{len(writer.spheres)} spheres, {len(writer.disks)} disks, {len(writer.cylinders)} cylinders, "
              f"{len(writer.lights)} lights, "
              f"{len(writer.cameras)} cameras, {len(writer.warnings)} warnings, "
              f"{clock.monotonic() - started:.2f} s", file=sys.stderr)
    return 0


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m lucerna_usd", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    commands = parser.add_subparsers(dest="command", required=True)
    c = commands.add_parser("convert", help="convert a stage to a lucerna scene file")
    c.add_argument("stage")
    c.add_argument("-o", "--output", required=True)
    c.add_argument("--frame", type=float)
    c.add_argument("--no-validate", action="store_true", help="skip the validators")
    c.add_argument("--strict", action="store_true",
                   help="stop on any validator error (default: findings are warnings)")
    c.add_argument("--quiet", action="store_true")
    c.add_argument("--variant", action="append", default=[], metavar="SET=NAME",
                   help="select variant NAME of set SET (in every prim that has it; "
                        "/PRIM:SET=NAME for one prim); repeatable")
    c.add_argument("--purpose", default="render",
                   help="purposes rendered besides default, comma-separated (render, proxy, guide)")
    c.add_argument("--no-payloads", action="store_true", help="do not load payloads")
    c.add_argument("--render-settings", metavar="PRIM",
                   help="the RenderSettings prim to follow (default: renderSettingsPrimPath, "
                        "else the first RenderSettings prim)")
    c.add_argument("--shutter", metavar="OPEN,CLOSE", type=_shutter,
                   help="the shutter in frames relative to the frame (default: the render "
                        "camera's shutter:open and shutter:close)")
    c.add_argument("--vectors", action="store_true",
                   help="the motion layers are asked for: where the shutter is closed, take "
                        "motion over half a frame each way, without blur")
    c.add_argument("--max-memory", type=int, metavar="BYTES",
                   help="refuse to decode an image that alone needs more (lucerna's --max-memory)")
    v = commands.add_parser("validate", help="print the validators' findings")
    v.add_argument("stage")
    args = parser.parse_args(argv)
    from . import start_heartbeat

    start_heartbeat()
    try:
        import numpy  # noqa: F401
        import OpenImageIO  # noqa: F401
        from pxr import Usd  # noqa: F401
    except ImportError as e:
        print(f"lucerna-usd: error: missing Python package ({e}); install the plugin's "
              f"requirements with: {sys.executable} -m pip install -r {REQUIREMENTS}",
              file=sys.stderr)
        return EXIT_MISSING_PACKAGE
    if args.command == "validate":
        stage, reason = _open(args.stage)
        if stage is None:
            _error(args.stage, "stage", reason)
            return EXIT_BAD_INPUT
        from .validate import validate

        findings = validate(stage)
        for f in findings:
            print(f"{f.severity}: {f}")
        return EXIT_BAD_INPUT if any(f.severity == "error" for f in findings) else 0
    if getattr(args, "max_memory", None):
        from . import images

        images.MAX_BYTES = args.max_memory
    try:
        purposes = tuple(p.strip() for p in args.purpose.split(",") if p.strip())
        unknown = [p for p in purposes if p not in ("render", "proxy", "guide")]
        if unknown:
            _error(args.stage, "--purpose", f"unknown purpose {unknown[0]!r} (render, proxy, guide)")
            return EXIT_BAD_INPUT
        return convert(args.stage, args.output, args.frame, args.no_validate, args.quiet,
                       args.strict, args.variant, purposes, not args.no_payloads,
                       args.render_settings, args.shutter, args.vectors)
    except Exception as e:  # a bug of the plugin: one line, the traceback on request
        if os.environ.get("LUCERNA_USD_DEBUG"):
            raise
        _error(args.stage, "usd plugin", f"internal error: {type(e).__name__}: {e} "
               "(LUCERNA_USD_DEBUG=1 shows the traceback)")
        return 1


if __name__ == "__main__":
    sys.exit(main())
