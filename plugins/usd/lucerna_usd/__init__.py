"""lucerna's USD plugin: opens a stage with usd-core (Pixar's own composition: references,
payloads, variants, instancing), validates it with `pxr.UsdValidation`, and converts the
composed stage into lucerna's scene file. `python -m lucerna_usd --help` describes the
command line the renderer calls."""


class StageError(Exception):
    """A stage that cannot be converted: `element` (a prim or property path, or a file
    element) and `reason`. The command line reports it and exits with status 2."""

    def __init__(self, element, reason):
        super().__init__(f"{element}: {reason}")
        self.element = element
        self.reason = reason
