"""Stage validation with usd-core's `pxr.UsdValidation` framework (the successor of
usdchecker's ComplianceChecker): every registered validator runs through one
`ValidationContext`, and each finding is reported with the prim or property paths it is
about. "Shader id not found in sdrRegistry" is not reported for the MaterialX and
RenderMan nodes lucerna reads: usd-core registers no definitions for them. Nor is
"invalid or unresolvable inputs:file" of a UDIM set (`<UDIM>` in the path): the normal-map
validator resolves the path as one file, which a set never is; the plugin reads its tiles
and warns about those it cannot."""

import re
from dataclasses import dataclass

from pxr import Usd, UsdValidation

from . import images, mtlx

_UNREGISTERED_SHADER = re.compile(r"shaderId '([^']+)' specified on shader prim .* not found in sdrRegistry")


@dataclass
class Finding:
    """One validation finding: `severity` is "error", "warning" or "info"."""

    severity: str
    validator: str
    sites: list
    message: str

    def __str__(self):
        where = ", ".join(self.sites) or "stage"
        return f"{where}: {self.message} [{self.validator}]"


_SEVERITY = {
    UsdValidation.ValidationErrorType.Error: "error",
    UsdValidation.ValidationErrorType.Warn: "warning",
    UsdValidation.ValidationErrorType.Info: "info",
}


def _site(site):
    if site.IsPrim():
        return str(site.GetPrim().GetPath())
    if site.IsProperty():
        return str(site.GetProperty().GetPath())
    layer = site.GetLayer()
    return layer.identifier if layer else ""


def validate(stage: Usd.Stage) -> list:
    """Runs every registered validator on `stage`; returns the findings, errors first."""
    registry = UsdValidation.ValidationRegistry()
    validators = registry.GetOrLoadAllValidators()
    context = UsdValidation.ValidationContext(validators)
    findings = []
    for error in context.Validate(stage):
        if error.HasNoError():
            continue
        validator = error.GetValidator()
        unregistered = _UNREGISTERED_SHADER.search(error.GetMessage())
        if unregistered and mtlx.node_family(unregistered.group(1)) is not None:
            # usd-core registers no MaterialX or RenderMan shader definitions; lucerna
            # reads these nodes itself (MaterialX's library defines them).
            continue
        if "unresolvable inputs:file" in error.GetMessage() and any(
                t in error.GetMessage() for t in images.UDIM_TOKENS):
            continue  # a UDIM set: resolved tile by tile when it is read (images.py)
        if "'anon:" in error.GetMessage() and ".mtlx" in error.GetMessage():
            continue  # a .mtlx document lucerna converted to an in-memory layer (mtlx.py)
        findings.append(Finding(
            severity=_SEVERITY.get(error.GetType(), "warning"),
            validator=validator.GetMetadata().name if validator else error.GetName(),
            sites=[s for s in (_site(s) for s in error.GetSites()) if s],
            message=error.GetMessage(),
        ))
    order = {"error": 0, "warning": 1, "info": 2}
    findings.sort(key=lambda f: order[f.severity])
    return findings
