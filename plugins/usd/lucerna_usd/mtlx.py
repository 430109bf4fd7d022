"""MaterialX: the standard library's node definitions, and .mtlx documents as USD layers.

Node ids. MaterialX shaders in USD carry their node definition's name as `info:id`
(`ND_standard_surface_surfaceshader`, `ND_image_color3`, ...). `node_family` turns an id
into the node's name (`standard_surface`, `image`) by the standard library that the
`MaterialX` Python package ships, so that one reader serves every type variant; the
library also gives each input's default value (`defaults`) and each output's type.

Referenced documents. usd-core ships no file-format plugin for .mtlx (usdMtlx is built
only with MaterialX support), so a reference, payload or sublayer naming a .mtlx file
fails to compose. `substitute_documents` looks through the layers the opened stage uses,
reads each .mtlx document with the `MaterialX` package and writes the USD that
usdMtlx would (`/MaterialX/Materials/<material>` with `outputs:mtlx:surface`), then points
the arc at that in-memory layer and the stage recomposes. Each material carries its shader and every node and node
graph it reads as children, so a reference to one material alone keeps its connections.
File names are resolved against the document (fileprefix and the document's directory);
colour spaces become USD colorSpace metadata."""

import os
import re

from pxr import Sdf

_LIBRARY = None

#: Node ids that are not MaterialX node definitions, by family.
_FAMILIES = {
    "UsdUVTexture": "UsdUVTexture", "UsdTransform2d": "UsdTransform2d",
    "UsdPrimvarReader_float": "UsdPrimvarReader", "UsdPrimvarReader_float2": "UsdPrimvarReader",
    "UsdPrimvarReader_float3": "UsdPrimvarReader", "UsdPrimvarReader_float4": "UsdPrimvarReader",
    "UsdPrimvarReader_int": "UsdPrimvarReader", "UsdPrimvarReader_string": "UsdPrimvarReader",
    "UsdPrimvarReader_normal": "UsdPrimvarReader", "UsdPrimvarReader_point": "UsdPrimvarReader",
    "UsdPrimvarReader_vector": "UsdPrimvarReader", "UsdPreviewSurface": "UsdPreviewSurface",
    "PxrTexture": "PxrTexture", "PxrNormalMap": "PxrNormalMap", "PxrManifold2D": "PxrManifold2D",
    "PxrSurface": "PxrSurface", "PxrDisney": "PxrDisney", "PxrDisneyBsdf": "PxrDisney",
}
_GROUPED = {"separate2": "separate", "separate3": "separate", "separate4": "separate",
            "combine2": "combine", "combine3": "combine", "combine4": "combine"}
_SIZES = {"float": 1, "integer": 1, "boolean": 1, "vector2": 2, "color3": 3, "vector3": 3,
          "color4": 4, "vector4": 4}


def library():
    """The MaterialX standard data library (loaded once), or None without the package."""
    global _LIBRARY
    if _LIBRARY is None:
        try:
            import MaterialX as mx
        except ImportError:
            _LIBRARY = False
            return None
        lib = mx.createDocument()
        mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)
        _LIBRARY = lib
    return _LIBRARY or None


def _nodedef(node_id):
    lib = library() if node_id.startswith("ND_") else None
    return lib.getNodeDef(node_id) if lib is not None else None


def node_family(node_id):
    """The node a shader id instantiates: `image` for ND_image_color3, `UsdUVTexture` for
    UsdUVTexture and ND_UsdUVTexture_23, ..."""
    node_id = str(node_id)
    if node_id in _FAMILIES:
        return _FAMILIES[node_id]
    nd = _nodedef(node_id)
    if nd is not None:
        name = nd.getNodeString()
    elif node_id.startswith("ND_"):
        name = re.sub(r"_[a-z0-9]+$", "", node_id[3:])  # ND_<node>_<type>
    else:
        return None
    return _GROUPED.get(name, name)


def output_type(node_id, output):
    """The MaterialX type of `output` of the node `node_id` defines ('' if unknown)."""
    nd = _nodedef(str(node_id))
    if nd is None:
        return ""
    out = nd.getOutput(output) if output else None
    if out is None:
        outs = nd.getActiveOutputs()
        out = outs[0] if outs else None
    return out.getType() if out is not None else nd.getType()


def output_size(node_id, output):
    """Components of the output (1 for float, 3 for color3, ...); 3 where unknown."""
    return _SIZES.get(output_type(node_id, output), 3)


def defaults(node_id):
    """{input name: default value} of a node definition (Python values: float, tuple,
    bool, str), empty where the library or the definition is missing."""
    nd = _nodedef(str(node_id))
    if nd is None:
        return {}
    out = {}
    for inp in nd.getActiveInputs():
        value = inp.getValue()
        if value is None:
            continue
        out[inp.getName()] = _python(value)
    return out


def _python(value):
    if isinstance(value, (bool, int, float, str)):
        return value
    try:
        return tuple(float(x) for x in value.asTuple())
    except AttributeError:
        return value


# ---- referenced .mtlx documents ---------------------------------------------------------

_VALUE_TYPES = {
    "float": Sdf.ValueTypeNames.Float, "integer": Sdf.ValueTypeNames.Int,
    "boolean": Sdf.ValueTypeNames.Bool, "string": Sdf.ValueTypeNames.String,
    "filename": Sdf.ValueTypeNames.Asset, "color3": Sdf.ValueTypeNames.Color3f,
    "color4": Sdf.ValueTypeNames.Color4f, "vector2": Sdf.ValueTypeNames.Float2,
    "vector3": Sdf.ValueTypeNames.Float3, "vector4": Sdf.ValueTypeNames.Float4,
    "matrix33": Sdf.ValueTypeNames.Matrix3d, "matrix44": Sdf.ValueTypeNames.Matrix4d,
    "surfaceshader": Sdf.ValueTypeNames.Token, "displacementshader": Sdf.ValueTypeNames.Token,
    "volumeshader": Sdf.ValueTypeNames.Token, "material": Sdf.ValueTypeNames.Token,
}


class DocumentError(Exception):
    """A .mtlx document that cannot be read."""


def document_layer(path):
    """The USD layer (anonymous, in memory) usdMtlx would make of the document `path`."""
    try:
        import MaterialX as mx
    except ImportError as e:
        raise DocumentError("the MaterialX Python package is not installed "
                            "(pip install MaterialX)") from e
    doc = mx.createDocument()
    try:
        mx.readFromXmlFile(doc, path)
    except Exception as e:  # MaterialX raises its own exception types
        raise DocumentError(str(e)) from e
    layer = Sdf.Layer.CreateAnonymous(os.path.basename(path) + ".usda")
    root = Sdf.CreatePrimInLayer(layer, "/MaterialX")
    root.specifier = Sdf.SpecifierDef
    materials = Sdf.CreatePrimInLayer(layer, "/MaterialX/Materials")
    materials.specifier = Sdf.SpecifierDef
    directory = os.path.dirname(os.path.abspath(path))
    writer = _DocumentWriter(layer, doc, directory)
    for material in doc.getMaterialNodes():
        writer.material(material)
    return layer


class _DocumentWriter:
    def __init__(self, layer, doc, directory):
        self.layer = layer
        self.doc = doc
        self.directory = directory
        self.doc_color_space = doc.getColorSpace() or ""

    def material(self, material):
        mpath = Sdf.Path("/MaterialX/Materials").AppendChild(_prim_name(material.getName()))
        spec = self.prim(mpath, "Material")
        written = {}
        for inp in material.getInputs():
            if inp.getType() != "surfaceshader":
                continue
            shader = inp.getConnectedNode()
            if shader is None:
                continue
            shader_path = self.node(shader, mpath, written)
            out = Sdf.AttributeSpec(spec, "outputs:mtlx:surface", Sdf.ValueTypeNames.Token)
            out.connectionPathList.explicitItems = [shader_path.AppendProperty("outputs:out")]

    def node(self, node, parent, written, graph=None):
        """Writes `node` (and what it reads) under `parent`; returns its prim path."""
        key = (graph.getName() if graph is not None else "", node.getName())
        if key in written:
            return written[key]
        path = parent.AppendChild(_prim_name(node.getName()))
        written[key] = path
        spec = self.prim(path, "Shader")
        nd = node.getNodeDef()
        node_id = nd.getName() if nd is not None else f"ND_{node.getCategory()}_{node.getType()}"
        attr = Sdf.AttributeSpec(spec, "info:id", Sdf.ValueTypeNames.Token, Sdf.VariabilityUniform)
        attr.default = node_id
        outputs = node.getOutputs() or (nd.getActiveOutputs() if nd is not None else [])
        names = [o.getName() for o in outputs] or ["out"]
        for out_name in names:
            Sdf.AttributeSpec(spec, f"outputs:{out_name}", Sdf.ValueTypeNames.Token)
        for inp in node.getInputs():
            self.input(inp, spec, parent, written, graph)
        return path

    def prim(self, path, type_name):
        spec = Sdf.CreatePrimInLayer(self.layer, path)
        spec.specifier = Sdf.SpecifierDef
        spec.typeName = type_name
        return spec

    def input(self, inp, spec, parent, written, graph):
        attr = _attribute(spec, "inputs:" + inp.getName(), inp.getType())
        upstream_graph = inp.getNodeGraphString()
        if inp.getNodeName():
            owner = graph if graph is not None else self.doc
            upstream = owner.getNode(inp.getNodeName())
            if upstream is not None:
                target = self.node(upstream, parent, written, graph)
                out = inp.getOutputString() or "out"
                attr.connectionPathList.explicitItems = [target.AppendProperty("outputs:" + out)]
            return
        if upstream_graph:
            ng = self.doc.getNodeGraph(upstream_graph)
            if ng is not None:
                target = self.graph(ng, parent.GetParentPath() if graph else parent, written)
                out = inp.getOutputString() or (ng.getOutputs()[0].getName() if ng.getOutputs() else "out")
                attr.connectionPathList.explicitItems = [target.AppendProperty("outputs:" + out)]
            return
        if inp.getInterfaceName() and graph is not None:
            attr.connectionPathList.explicitItems = [
                parent.AppendProperty("inputs:" + inp.getInterfaceName())]
            return
        self.value(inp, attr)

    def value(self, inp, attr):
        """Sets `attr` to the value `inp` states, if any: file names resolved and with their
        colour space."""
        if not inp.hasValueString():
            return
        if inp.getType() == "filename":
            attr.default = Sdf.AssetPath(self.resolve(inp.getResolvedValueString(), inp.getValueString()))
            color_space = inp.getColorSpace() or inp.getActiveColorSpace() or self.doc_color_space
            if color_space:
                attr.SetInfo("colorSpace", color_space)
            return
        try:
            attr.default = _usd_value(inp.getValue(), inp.getType())
        except (TypeError, ValueError):
            pass  # a value MaterialX cannot parse: the input keeps its default

    def graph(self, ng, parent, written):
        key = ("graph", ng.getName())
        if key in written:
            return written[key]
        path = parent.AppendChild(_prim_name(ng.getName()))
        written[key] = path
        spec = self.prim(path, "NodeGraph")
        for inp in ng.getInputs():
            self.value(inp, _attribute(spec, "inputs:" + inp.getName(), inp.getType()))
        for out in ng.getOutputs():
            attr = _attribute(spec, "outputs:" + out.getName(), out.getType())
            node = ng.getNode(out.getNodeName()) if out.getNodeName() else None
            if node is not None:
                target = self.node(node, path, written, ng)
                attr.connectionPathList.explicitItems = [
                    target.AppendProperty("outputs:" + (out.getOutputString() or "out"))]
        return path

    def resolve(self, name, unprefixed):
        """The file `name` (fileprefix applied) names, relative to the document. Where that
        file does not exist but the value without the prefix does, the latter: documents
        that repeat their prefix in the value exist in the wild."""
        def absolute(n):
            if not n or os.path.isabs(n) or "://" in n:
                return n
            return os.path.normpath(os.path.join(self.directory, n))
        path = absolute(name)
        if path != absolute(unprefixed) and not os.path.exists(path) and os.path.exists(absolute(unprefixed)):
            return absolute(unprefixed)
        return path


def _attribute(spec, name, mtlx_type):
    return Sdf.AttributeSpec(spec, name, _VALUE_TYPES.get(mtlx_type, Sdf.ValueTypeNames.Token))


def _prim_name(name):
    name = re.sub(r"[^A-Za-z0-9_]", "_", name)
    return name if name and not name[0].isdigit() else "_" + name


def _usd_value(value, type_name):
    from pxr import Gf
    if type_name in ("float",):
        return float(value)
    if type_name == "integer":
        return int(value)
    if type_name == "boolean":
        return bool(value)
    if type_name == "string":
        return str(value)
    numbers = [float(x) for x in value.asTuple()]
    return {"color3": Gf.Vec3f, "vector3": Gf.Vec3f, "color4": Gf.Vec4f, "vector4": Gf.Vec4f,
            "vector2": Gf.Vec2f}.get(type_name, lambda *a: numbers)(*numbers)


def substitute_documents(stage, warn):
    """Points every arc to a .mtlx document in the layers `stage` uses (sublayers,
    references and payloads, in variants too) at the document's USD layer; the stage
    recomposes. Returns the layers made, which must live as long as the stage."""
    keep = []
    converted = {}
    done = set()
    while True:
        changed = False
        for layer in stage.GetUsedLayers():
            if layer.identifier in done:
                continue
            done.add(layer.identifier)
            anchor = layer.realPath or layer.identifier
            for asset in layer.GetCompositionAssetDependencies():
                if not asset.lower().endswith(".mtlx"):
                    continue
                path = Sdf.ComputeAssetPathRelativeToLayer(layer, asset)
                if path not in converted:
                    try:
                        converted[path] = document_layer(path)
                        keep.append(converted[path])
                    except (DocumentError, OSError) as e:
                        warn(anchor, f"MaterialX document {asset!r} cannot be read ({e}): its "
                             "materials are missing")
                        converted[path] = None
                if converted[path] is not None:
                    layer.UpdateCompositionAssetDependency(asset, converted[path].identifier)
                    changed = True
        if not changed:
            return keep
