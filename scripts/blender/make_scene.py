"""Build a small glass/metal scene with bpy, export it with Blender's glTF exporter and
optionally render it with Cycles as a reference for `striae render scene.glb`.

    python3 scripts/blender/make_scene.py                       # -> crates/striae/scenes/blender/blender-scene.glb
    python3 scripts/blender/make_scene.py --cycles --spp 4096 --threads 2  # + blender-scene-cycles.exr / .png (the committed ones:
                                                                              # 82 s)
    python3 scripts/blender/make_scene.py --measure-units DIR   # Cycles' light units on a diffuse plane

Needs a Python that imports `bpy` (written against bpy 5.0.1: `pip install bpy==5.0.1`, CPython
3.11). Inside a Blender binary, arguments go after `--` (`blender -b -P make_scene.py -- --cycles`).

The Cycles reference: CPU path tracing, no denoising, no adaptive sampling, a 1-pixel box filter
(striae's pixel filter), 15 bounces of every kind (16 path segments, striae's default
`max_depth`), no clamping, light threshold 0, Filter Glossy 0, caustics on, a black world; view
transform Standard, look None, exposure 0, gamma 1; the EXR is linear Rec. 709 32-bit float RGB.

The scene (Blender z-up; the exporter writes glTF's y-up): a 6 x 6 floor (base 0.8, metallic 0,
roughness 0.8), a glass sphere (transmission 1, IOR 1.5, roughness 0, a Volume Absorption node
exported as KHR_materials_volume), a copper-coloured metal cube (metallic 1, roughness 0.3), a
point light of 400 W (radius 0), a small emissive panel facing down, a perspective camera and a
black world.

Units. Blender's glTF exporter in its default "Standard" lighting mode
(`export_import_convert_lighting_mode = 'SPEC'`, io_scene_gltf2/blender/exp/lights.py, Blender
5.0.1) writes a point or spot light of power P watts as `intensity = P / (4 pi) * 683 * 2^exposure`
candela (P times the light's area when its `normalize` is off; a spot's cone does not concentrate
the power) and a sun of strength S W/m^2 as `intensity = S * 2^exposure` "lux", without the 683
(its importer divides a sun's lux by 683, so a sun does not survive the round trip). Cycles gives
a point or spot light of P watts the radiant intensity P / (4 pi) W/sr and a sun of S the
irradiance S W/m^2 (`--measure-units`: 1.0000 of the radiometric radiance on a Lambertian plane
for all three). So for Blender's files `candela / 683` is Cycles' W/sr exactly, and a sun's
`intensity` is Cycles' W/m^2 as written: KHR_lights_punctual's `lux / 683` makes a Blender sun
683 times too dark.

Volume. The exporter writes KHR_materials_volume only when a "glTF Material Output" node group
with a non-zero "Thickness" input is in the material; `attenuationColor` is the Volume Absorption
node's Color and `attenuationDistance` 1 / its Density. glTF's transmittance over
`attenuationDistance` is `attenuationColor`, i.e. sigma_a = -ln(c) / d, while Cycles' Volume
Absorption has sigma_a = (1 - Color) * Density. Before the Cycles render the script therefore sets
the node's Color to 1 + ln(c) (Density unchanged), so that Cycles absorbs as the glTF file says.
"""

import argparse
import json
import math
import os
import pathlib
import sys
import time

import bpy

ROOT = pathlib.Path(__file__).resolve().parents[2]
OUT_DIR = ROOT / "crates/striae/scenes/blender"

RES = (160, 120)
GLASS_ATTENUATION_COLOR = (0.55, 0.8, 0.95)
GLASS_ATTENUATION_DISTANCE = 1.0
POINT_POWER_W = 400.0
PANEL_STRENGTH = 6.0


def reset():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    world = bpy.data.worlds.new("black")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0, 0, 0, 1)
    scene.world = world
    scene.render.resolution_x, scene.render.resolution_y = RES
    scene.render.resolution_percentage = 100
    return scene


def principled(name, base, metallic=0.0, roughness=0.5, transmission=0.0, ior=1.5):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*base, 1.0)
    bsdf.inputs["Metallic"].default_value = metallic
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["Transmission Weight"].default_value = transmission
    bsdf.inputs["IOR"].default_value = ior
    return mat


def gltf_output_group():
    """The node group the glTF exporter reads `Thickness` (and `Occlusion`) from, as its own
    "glTF Material Output" operator builds it (io_scene_gltf2/blender/com/material_helpers.py)."""
    name = "glTF Material Output"
    if name in bpy.data.node_groups:
        return bpy.data.node_groups[name]
    group = bpy.data.node_groups.new(name, "ShaderNodeTree")
    group.interface.new_socket("Occlusion", socket_type="NodeSocketFloat")
    thickness = group.interface.new_socket("Thickness", socket_type="NodeSocketFloat")
    thickness.default_value = 0.0
    group.nodes.new("NodeGroupOutput")
    group.nodes.new("NodeGroupInput")
    return group


def glass_material():
    mat = principled("glass", (1.0, 1.0, 1.0), roughness=0.0, transmission=1.0, ior=1.5)
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    absorb = nodes.new("ShaderNodeVolumeAbsorption")
    absorb.inputs["Color"].default_value = (*GLASS_ATTENUATION_COLOR, 1.0)
    absorb.inputs["Density"].default_value = 1.0 / GLASS_ATTENUATION_DISTANCE
    links.new(absorb.outputs["Volume"], nodes["Material Output"].inputs["Volume"])
    settings = nodes.new("ShaderNodeGroup")
    settings.node_tree = gltf_output_group()
    settings.inputs["Thickness"].default_value = 1.0  # the sphere's diameter
    return mat


def emissive_material(strength):
    mat = principled("panel", (0.0, 0.0, 0.0), roughness=1.0)
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Emission Color"].default_value = (1.0, 0.95, 0.85, 1.0)
    bsdf.inputs["Emission Strength"].default_value = strength
    return mat


def build_scene():
    scene = reset()

    bpy.ops.mesh.primitive_plane_add(size=6.0, location=(0, 0, 0))
    floor = bpy.context.object
    floor.name = "floor"
    floor.data.materials.append(principled("floor", (0.8, 0.8, 0.8), metallic=0.0, roughness=0.8))

    bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16, radius=0.5, location=(-0.65, 0.1, 0.5))
    glass = bpy.context.object
    glass.name = "glass"
    bpy.ops.object.shade_smooth()
    glass.data.materials.append(glass_material())

    bpy.ops.mesh.primitive_cube_add(size=0.7, location=(0.7, 0.35, 0.35), rotation=(0, 0, math.radians(30)))
    metal = bpy.context.object
    metal.name = "metal"
    metal.data.materials.append(principled("copper", (0.95, 0.64, 0.54), metallic=1.0, roughness=0.3))

    # A 0.8 x 0.8 panel at z = 2.6 facing down (-z): the plane's normal is +z before the flip.
    bpy.ops.mesh.primitive_plane_add(size=0.8, location=(-0.8, 0.9, 2.6), rotation=(math.pi, 0, 0))
    panel = bpy.context.object
    panel.name = "panel"
    panel.data.materials.append(emissive_material(PANEL_STRENGTH))

    light_data = bpy.data.lights.new("lamp", "POINT")
    light_data.energy = POINT_POWER_W
    light_data.shadow_soft_size = 0.0
    light_data.color = (1.0, 1.0, 1.0)
    lamp = bpy.data.objects.new("lamp", light_data)
    lamp.location = (1.6, -1.2, 3.0)
    scene.collection.objects.link(lamp)

    cam_data = bpy.data.cameras.new("camera")
    cam_data.sensor_fit = "VERTICAL"
    cam_data.angle_y = math.radians(32.0)
    cam = bpy.data.objects.new("camera", cam_data)
    cam.location = (0.0, -4.6, 2.3)
    target = (0.0, 0.2, 0.35)
    direction = [t - p for t, p in zip(target, cam.location)]
    from mathutils import Vector

    cam.rotation_euler = Vector(direction).to_track_quat("-Z", "Y").to_euler()
    scene.collection.objects.link(cam)
    scene.camera = cam
    return scene


def export_glb(path):
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    bpy.ops.export_scene.gltf(
        filepath=str(path),
        export_format="GLB",
        export_cameras=True,
        export_lights=True,
        export_import_convert_lighting_mode="SPEC",
        export_yup=True,
        export_apply=True,
        export_extras=False,
        export_draco_mesh_compression_enable=False,
    )
    return path


def enable_cycles(scene, spp, threads=0):
    import addon_utils

    addon_utils.enable("cycles", default_set=True)
    scene.render.engine = "CYCLES"
    cycles = scene.cycles
    cycles.device = "CPU"
    cycles.samples = spp
    cycles.use_adaptive_sampling = False
    cycles.use_denoising = False
    cycles.max_bounces = 15  # 16 path segments, striae's max_depth = 16
    for key in ("diffuse_bounces", "glossy_bounces", "transmission_bounces", "volume_bounces",
                "transparent_max_bounces"):
        setattr(cycles, key, 15)
    cycles.caustics_reflective = True
    cycles.caustics_refractive = True
    cycles.blur_glossy = 0.0
    cycles.sample_clamp_direct = 0.0
    cycles.sample_clamp_indirect = 0.0
    cycles.light_sampling_threshold = 0.0
    cycles.pixel_filter_type = "BOX"
    cycles.filter_width = 1.0
    scene.render.film_transparent = False
    scene.render.threads_mode = "FIXED" if threads else "AUTO"
    if threads:
        scene.render.threads = threads
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    scene.display_settings.display_device = "sRGB"


def save(scene, stem):
    """Render once and write `stem.exr` (linear, 32-bit float RGB) and `stem.png` (sRGB)."""
    t0 = time.time()
    bpy.ops.render.render(write_still=False)
    seconds = time.time() - t0
    image = bpy.data.images["Render Result"]
    settings = scene.render.image_settings
    settings.file_format = "OPEN_EXR"
    settings.color_depth = "32"
    settings.color_mode = "RGB"
    settings.exr_codec = "ZIP"
    image.save_render(f"{stem}.exr", scene=scene)
    settings.file_format = "PNG"
    settings.color_depth = "8"
    settings.color_mode = "RGB"
    image.save_render(f"{stem}.png", scene=scene)
    return seconds


def render_cycles(scene, stem, spp, threads=0):
    glass = bpy.data.materials["glass"]
    absorb = next(n for n in glass.node_tree.nodes if n.bl_idname == "ShaderNodeVolumeAbsorption")
    assert min(GLASS_ATTENUATION_COLOR) > math.exp(-1.0), "1 + ln(c) must stay >= 0"
    absorb.inputs["Color"].default_value = (*[1.0 + math.log(c) for c in GLASS_ATTENUATION_COLOR], 1.0)
    enable_cycles(scene, spp, threads)
    return save(scene, stem)


def read_exr(path):
    """The EXR's pixels as a list of rows of (r, g, b), row 0 at the top."""
    image = bpy.data.images.load(str(path))
    w, h = image.size
    px = list(image.pixels)
    c = image.channels
    rows = [[tuple(px[(y * w + x) * c:(y * w + x) * c + 3]) for x in range(w)] for y in range(h)]
    bpy.data.images.remove(image)
    return rows[::-1]


def measure_units(out_dir, spp=16):
    """Cycles' radiance on a Lambertian plane (albedo 0.8) straight under a point light and a spot
    (100 W, radius 0, 2 above the plane) and a sun (3 W/m^2, angle 0), seen by an orthographic
    camera 0.02 wide; against the radiometric 0.8 / pi * P / (4 pi h^2) (0.8 / pi * S for the
    sun) and against the value the exporter's glTF intensity gives read as I = cd / 683 W/sr,
    E = lx / 683 W/m^2 (KHR_lights_punctual's photometric units). Writes DIR/units.json."""
    power, height, sun = 100.0, 2.0, 3.0
    results = {}
    for kind in ("POINT", "SPOT", "SUN"):
        scene = reset()
        bpy.ops.mesh.primitive_plane_add(size=20.0)
        plane = bpy.context.object
        mat = bpy.data.materials.new("lambert")
        mat.use_nodes = True
        nodes = mat.node_tree.nodes
        nodes.remove(nodes["Principled BSDF"])
        diffuse = nodes.new("ShaderNodeBsdfDiffuse")
        diffuse.inputs["Color"].default_value = (0.8, 0.8, 0.8, 1.0)
        diffuse.inputs["Roughness"].default_value = 0.0
        mat.node_tree.links.new(diffuse.outputs["BSDF"], nodes["Material Output"].inputs["Surface"])
        plane.data.materials.append(mat)
        data = bpy.data.lights.new("l", kind)
        data.energy = sun if kind == "SUN" else power
        if kind != "SUN":
            data.shadow_soft_size = 0.0
        else:
            data.angle = 0.0
        lamp = bpy.data.objects.new("l", data)
        lamp.location = (0, 0, height)
        scene.collection.objects.link(lamp)
        cam_data = bpy.data.cameras.new("c")
        cam_data.type = "ORTHO"
        cam_data.ortho_scale = 0.02
        cam = bpy.data.objects.new("c", cam_data)
        cam.location = (0, 0, height + 1.0)
        scene.collection.objects.link(cam)
        scene.camera = cam
        scene.render.resolution_x = scene.render.resolution_y = 4
        enable_cycles(scene, spp)
        stem = pathlib.Path(out_dir) / f"units-{kind.lower()}"
        save(scene, str(stem))
        rows = read_exr(f"{stem}.exr")
        value = sum(p[0] for row in rows for p in row) / 16.0
        if kind == "SUN":
            expected = 0.8 / math.pi * sun
            intensity = sun  # what the exporter writes: lux = W/m^2, no 683
            from_gltf = 0.8 / math.pi * intensity / 683.0
        else:
            expected = 0.8 / math.pi * power / (4 * math.pi) / height**2
            intensity = power / (4 * math.pi) * 683.0  # candela, as the exporter writes it
            from_gltf = 0.8 / math.pi * intensity / 683.0 / height**2
        results[kind.lower()] = {"cycles": value, "radiometric": expected, "gltf_over_683": from_gltf,
                                 "gltf_intensity": intensity}
        print(f"{kind.lower():5s}: Cycles {value:.5f}  radiometric {expected:.5f} (ratio {value / expected:.4f})  "
              f"exported {intensity:.3f} {'lx' if kind == 'SUN' else 'cd'}, /683 -> {from_gltf:.5f} "
              f"(Cycles / that {value / from_gltf:.4f})")
    (pathlib.Path(out_dir) / "units.json").write_text(json.dumps(results, indent=1) + "\n")
    return results


def main(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-o", "--output", default=str(OUT_DIR / "blender-scene.glb"), help="the GLB to write")
    parser.add_argument("--cycles", action="store_true", help="also render with Cycles: STEM-cycles.exr and .png")
    parser.add_argument("--spp", type=int, default=512, help="Cycles samples per pixel (default 512)")
    parser.add_argument("--res", default=f"{RES[0]}x{RES[1]}", help="Cycles resolution WxH (default 160x120)")
    parser.add_argument("--threads", type=int, default=0, help="Cycles threads (default: all)")
    parser.add_argument("--measure-units", metavar="DIR", help="render the unit check into DIR and print it")
    args = parser.parse_args(argv)

    if args.measure_units:
        os.makedirs(args.measure_units, exist_ok=True)
        measure_units(args.measure_units)
        return
    scene = build_scene()
    glb = export_glb(args.output)
    print(f"wrote {glb} ({glb.stat().st_size} bytes)")
    if args.cycles:
        w, h = (int(v) for v in args.res.split("x"))
        scene.render.resolution_x, scene.render.resolution_y = w, h
        stem = str(glb.with_suffix("")) + "-cycles"
        seconds = render_cycles(scene, stem, args.spp, args.threads)
        print(f"wrote {stem}.exr and {stem}.png: Cycles CPU, {w}x{h}, {args.spp} spp, {seconds:.1f} s")


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:])
