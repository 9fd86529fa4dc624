"""striae scratches: scratch settings on Blender materials, written by Blender's glTF exporter as
the material extension `STRIAE_materials_scratches`.

The extension object holds the keys of striae's `[materials.NAME.scratches]` table
(docs/scenes.md, docs/scratched.md) with the same values as in TOML. Only the keys set on the
material are written (a key reads as set once it has been given a value, in the panel or from
Python, until its "x" button or `property_unset` clears it); file paths (`curves`, `table`) are
written relative to the .glb's folder, with `/` separators. `extra` takes further keys as a JSON
object (e.g. `{"m": 64, "pattern": {"kind": "swirl", "count": 1500}}`); the panel's keys win
over it.

Loaded as a Blender 4.2+ extension (blender_manifest.toml) or as a legacy add-on (bl_info).
"""

import json
import os

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

bl_info = {
    "name": "striae scratches",
    "author": "striae",
    "version": (0, 1, 0),
    "blender": (4, 2, 0),
    "location": "Properties > Material > striae scratches",
    "description": "Scratch settings for striae, exported to glTF as STRIAE_materials_scratches",
    "category": "Import-Export",
}

EXTENSION = "STRIAE_materials_scratches"

# The keys the panel offers, in the order it draws them and the extension writes them.
KEYS = (
    "model", "profile", "walls", "roughness", "fresnel",
    "setting", "length", "width", "threshold", "layers", "seed", "layer_mix", "orientation",
    "lean", "explicit",
    "curves", "depth", "taper", "wear", "wear_length",
    "table",
)
PATH_KEYS = ("curves", "table")
FLOAT_KEYS = ("roughness", "length", "width", "threshold", "depth", "taper", "wear", "wear_length")


def _enum(*values):
    return [(v, v, "") for v in values]


class StriaeScratches(bpy.types.PropertyGroup):
    enabled: BoolProperty(name="Scratches", description="Write STRIAE_materials_scratches for this material", default=False)
    model: EnumProperty(name="Model", items=_enum("default", "seed"), default="default",
                        description="Which defaults fill the keys left out")
    profile: StringProperty(name="Profile", default="v:angle=90",
                            description="Groove profile, as `striae precompute --profile` (v:angle=90, round:depth=0.3, ...)")
    walls: EnumProperty(name="Walls", items=_enum("diffuse", "specular", "dielectric"), default="diffuse",
                        description="Wall micro-BRDF")
    roughness: FloatProperty(name="Wall roughness", min=0.0, max=1.0, default=0.0,
                             description="GGX alpha of dielectric walls or of a metal's specular walls")
    fresnel: EnumProperty(name="Fresnel", items=_enum("seed", "walls"), default="seed",
                          description="Where Fresnel is applied")
    setting: IntProperty(name="Setting", min=1, max=2, default=1,
                         description="The seed's Table 1 (excludes length, width, threshold)")
    length: FloatProperty(name="Length", min=1e-6, max=1e6, default=0.3, precision=4,
                          description="Scratch length (uv units)")
    width: FloatProperty(name="Width", min=1e-6, max=1e6, default=0.001, precision=5,
                         description="Scratch width (uv units)")
    threshold: FloatProperty(name="Threshold", min=1e-6, max=1.0, default=0.1, precision=3,
                             description="Worley threshold tau, (0, 1]")
    layers: IntProperty(name="Layers", min=1, max=64, default=8, description="Number of scratch layers K")
    seed: IntProperty(name="Seed", min=0, default=1, description="Seed of the layer set (and of the curves' wear)")
    layer_mix: EnumProperty(name="Layer mix", items=_enum("stochastic", "union", "sum", "max"),
                            default="stochastic",
                            description="How layers (and curves) covering a footprint combine")
    orientation: EnumProperty(name="Orientation", items=_enum("layer", "random"), default="layer",
                              description="A direction per layer, or per scratch")
    lean: BoolProperty(name="Lean", default=False, description="Lean each scratch lobe's frame as the tapered groove's walls lean")
    explicit: BoolProperty(name="Explicit", default=False, description="Carve real grooves into rectangles and boxes")
    curves: StringProperty(name="Curves (SVG)", subtype="FILE_PATH", default="",
                           description="An SVG whose stroked paths are scratches")
    depth: FloatProperty(name="Depth", min=1e-6, max=1.0, default=1.0, description="Curves' depth ratio, (0, 1]")
    taper: FloatProperty(name="Taper", min=0.0, default=0.0, precision=4,
                         description="Length over which each curve end tapers (drawing units)")
    wear: FloatProperty(name="Wear", min=0.0, max=0.999, default=0.0, description="The most of the depth wear takes, [0, 1)")
    wear_length: FloatProperty(name="Wear length", min=1e-6, default=0.05, precision=4,
                               description="Correlation length of the wear (required with wear)")
    table: StringProperty(name="Table (.npz)", subtype="FILE_PATH", default="",
                          description="A precomputed scratch table instead of the table keys")
    extra: StringProperty(name="Extra (JSON)", default="",
                          description="Further scratches keys as a JSON object; the keys above win")


def _number(value):
    """A float property's value as the decimal the user typed (Blender stores float32)."""
    return float(f"{value:.7g}")


def _relative(path, directory):
    path = bpy.path.abspath(path)
    if directory:
        try:
            path = os.path.relpath(path, directory)
        except ValueError:  # another drive on Windows
            pass
    return path.replace(os.sep, "/")


def scratches_object(props, glb_directory=None):
    """The STRIAE_materials_scratches object of one material's settings (None if disabled).

    Raises ValueError when `extra` is not a JSON object."""
    if not props.enabled:
        return None
    out = {}
    if props.extra.strip():
        extra = json.loads(props.extra)
        if not isinstance(extra, dict):
            raise ValueError(f"`extra` must be a JSON object, got {props.extra!r}")
        out.update(extra)
    for key in KEYS:
        if not props.is_property_set(key):
            continue
        value = getattr(props, key)
        if key in PATH_KEYS:
            if not value:
                continue
            value = _relative(value, glb_directory)
        elif key in FLOAT_KEYS:
            value = _number(value)
        out[key] = value
    return out


class glTF2ExportUserExtension:
    """The glTF exporter's hook (io_scene_gltf2 instantiates it once per export)."""

    def __init__(self):
        from io_scene_gltf2.io.com.gltf2_io_extensions import Extension

        self.Extension = Extension

    def gather_material_hook(self, gltf2_material, blender_material, export_settings):
        props = getattr(blender_material, "striae_scratches", None)
        if props is None:
            return
        directory = os.path.dirname(os.path.abspath(export_settings["gltf_filepath"]))
        try:
            obj = scratches_object(props, directory)
        except ValueError as error:
            export_settings["log"].error(f"{EXTENSION} on material {blender_material.name!r}: {error}")
            return
        if obj is None:
            return
        if gltf2_material.extensions is None:
            gltf2_material.extensions = {}
        gltf2_material.extensions[EXTENSION] = self.Extension(name=EXTENSION, extension=obj, required=False)


class STRIAE_OT_unset_scratch_key(bpy.types.Operator):
    bl_idname = "striae.unset_scratch_key"
    bl_label = "Leave out"
    bl_description = "Leave this key out of the glTF extension (striae's default applies)"
    bl_options = {"REGISTER", "UNDO", "INTERNAL"}

    key: StringProperty()

    def execute(self, context):
        material = context.material
        if material is not None:
            material.striae_scratches.property_unset(self.key)
        return {"FINISHED"}


class STRIAE_PT_scratches(bpy.types.Panel):
    bl_label = "striae scratches"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "material"
    bl_options = {"DEFAULT_CLOSED"}

    @classmethod
    def poll(cls, context):
        return context.material is not None

    def draw_header(self, context):
        self.layout.prop(context.material.striae_scratches, "enabled", text="")

    def draw(self, context):
        props = context.material.striae_scratches
        layout = self.layout
        layout.active = props.enabled
        groups = (
            ("Groove", ("model", "profile", "walls", "roughness", "fresnel")),
            ("Layers", ("setting", "length", "width", "threshold", "layers", "seed", "layer_mix",
                        "orientation", "lean", "explicit")),
            ("Curves", ("curves", "depth", "taper", "wear", "wear_length")),
            ("Table", ("table",)),
        )
        for title, keys in groups:
            box = layout.box()
            box.label(text=title)
            for key in keys:
                row = box.row(align=True)
                is_set = props.is_property_set(key)
                row.prop(props, key)
                sub = row.row(align=True)
                sub.enabled = is_set
                op = sub.operator(STRIAE_OT_unset_scratch_key.bl_idname, text="", icon="X" if is_set else "BLANK1",
                                  emboss=is_set)
                op.key = key
        layout.prop(props, "extra")
        written = [k for k in KEYS if props.is_property_set(k)]
        layout.label(text="Writes: " + (", ".join(written) if written else "striae's defaults"))
        if props.is_property_set("setting") and any(props.is_property_set(k) for k in ("length", "width", "threshold")):
            layout.label(text="setting excludes length, width and threshold", icon="ERROR")


classes = (StriaeScratches, STRIAE_OT_unset_scratch_key, STRIAE_PT_scratches)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Material.striae_scratches = PointerProperty(type=StriaeScratches)


def unregister():
    del bpy.types.Material.striae_scratches
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
