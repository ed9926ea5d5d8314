"""The Blender worker: a script run by the Blender environment's interpreter (``.venv-blender``).

It imports bpy and numpy only (never brdffit or jax: it runs under another interpreter, with
numpy < 2). Protocol (``brdffit.cycles.Worker`` is the other side):

- On start it writes one line ``{"ready": true, "blender": "5.0.1"}``.
- Then, per line read on stdin, one JSON request ``{"id": n, "op": OP, "args": {...}, "out": DIR}``
  and one JSON reply line ``{"id": n, "ok": true, "result": {...}}`` or
  ``{"id": n, "ok": false, "error": "one line"}``. Images go through files: a result names the
  ``.npy`` files it wrote in ``out``.
- End of stdin (or ``{"op": "quit"}``) ends the worker.

Blender writes its own progress to the C-level stdout, so the replies go through a duplicate of the
original stdout descriptor and descriptor 1 is pointed at stderr before bpy is imported.

A material is ``{"distribution": "GGX" | "MULTI_GGX", "inputs": {Principled BSDF socket: value}}``
(``blender:principled``'s ``native()``); colours may be given as 3 values (alpha 1 is added).
"""

import json
import os
import sys
import traceback

_PROTO = os.fdopen(os.dup(1), "w", buffering=1)
os.dup2(2, 1)
sys.stdout = sys.stderr

import bpy  # noqa: E402
import numpy as np  # noqa: E402
from mathutils import Vector  # noqa: E402

#: The Principled BSDF inputs a native material may set (the opaque ones brdffit uses, and those
#: a caller may pin); anything else is refused, so a typo is an error rather than ignored.
SOCKETS = ("Base Color", "Metallic", "Roughness", "IOR", "Specular IOR Level", "Specular Tint",
           "Diffuse Roughness", "Coat Weight", "Coat Roughness", "Coat IOR", "Coat Tint",
           "Sheen Weight", "Sheen Roughness", "Sheen Tint", "Anisotropic", "Subsurface Weight",
           "Transmission Weight", "Alpha", "Emission Strength")
REPORTED = ("Base Color", "Metallic", "Roughness", "IOR", "Specular IOR Level", "Specular Tint",
            "Diffuse Roughness", "Coat Weight", "Sheen Weight")


class Refused(Exception):
    """A request the worker cannot do; its message is the reply's one line."""


def reset():
    bpy.ops.wm.read_factory_settings(use_empty=True)


def cycles_scene(width, height, spp):
    """The current scene set up for Cycles on the CPU: direct light only, no denoising, box filter,
    linear 32-bit EXR output, no view transform, exposure 1, a black world."""
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = int(spp)
    sc.cycles.use_denoising = False
    sc.cycles.use_adaptive_sampling = False
    sc.cycles.max_bounces = 0  # direct light only: the pixel is f (n.l) E
    sc.cycles.pixel_filter_type = "BOX"
    sc.cycles.filter_width = 1.0
    sc.cycles.film_exposure = 1.0
    sc.cycles.seed = 0
    sc.render.resolution_x = int(width)
    sc.render.resolution_y = int(height)
    sc.render.resolution_percentage = 100
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.image_settings.color_depth = "32"
    sc.view_settings.view_transform = "Standard"
    sc.view_settings.look = "None"
    sc.view_settings.exposure = 0.0
    sc.view_settings.gamma = 1.0
    world = bpy.data.worlds.new("black")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    sc.world = world
    return sc


def principled_material(native, name="brdffit"):
    """A material holding one Principled BSDF set from a native dict."""
    if not isinstance(native, dict) or set(native) - {"distribution", "inputs"}:
        raise Refused(f"a material is {{'distribution': ..., 'inputs': {{...}}}}, got {native!r:.200}")
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    node = mat.node_tree.nodes["Principled BSDF"]
    dist = native.get("distribution", "GGX")
    if dist not in ("GGX", "MULTI_GGX"):
        raise Refused(f"distribution {dist!r}: Cycles' Principled BSDF takes 'GGX' or 'MULTI_GGX'")
    node.distribution = dist
    for key, value in native.get("inputs", {}).items():
        if key not in SOCKETS:
            raise Refused(f"unknown Principled BSDF input {key!r}; known: {', '.join(SOCKETS)}")
        socket = node.inputs[key]
        if isinstance(value, (list, tuple)):
            value = [float(v) for v in value]
            if len(value) == 3 and len(socket.default_value) == 4:
                value = value + [1.0]
            socket.default_value = value
        else:
            socket.default_value = float(value)
    return mat


def material_of(args):
    """The request's material: ``"material"``, a native dict, or ``"blend": [path, name]``, a
    material appended from a .blend file (what a user of an exported file renders)."""
    if "blend" in args:
        path, name = args["blend"]
        with bpy.data.libraries.load(path, link=False) as (source, target):
            if name not in source.materials:
                raise Refused(f"{path}: no material {name!r}; it has {', '.join(source.materials) or 'none'}")
            target.materials = [name]
        return target.materials[0]
    return principled_material(args["material"])


def add_sun(sc, irradiance):
    light = bpy.data.lights.new("sun", "SUN")
    light.angle = 0.0  # a delta light: one direction
    light.energy = float(irradiance)  # W/m^2 on a surface facing the sun
    sun = bpy.data.objects.new("sun", light)
    sc.collection.objects.link(sun)
    sun.rotation_mode = "QUATERNION"
    return sun


def point_towards(obj, d):
    """Turn obj so that its local +z points along d (a sun shines along -z, a camera looks down -z)."""
    obj.rotation_quaternion = Vector(d).normalized().to_track_quat("Z", "Y")


def add_camera(sc, ortho_scale):
    cam_data = bpy.data.cameras.new("camera")
    cam_data.type = "ORTHO"
    cam_data.ortho_scale = float(ortho_scale)
    cam = bpy.data.objects.new("camera", cam_data)
    sc.collection.objects.link(cam)
    sc.camera = cam
    cam.rotation_mode = "QUATERNION"
    return cam


def render_rgb(sc, path):
    """Render the scene to a linear EXR at path and return it as (rows from the top, cols, 3)."""
    sc.render.filepath = path
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(path, check_existing=False)
    try:
        a = np.empty(len(img.pixels), np.float32)
        img.pixels.foreach_get(a)
        w, h = img.size
    finally:
        bpy.data.images.remove(img)
    return a.reshape(h, w, 4)[::-1, :, :3]  # Blender's rows run bottom to top


def directions(rows, name):
    a = np.asarray(rows, np.float64).reshape(-1, 3)
    n = np.linalg.norm(a, axis=1, keepdims=True)
    if not np.all(np.isfinite(a)) or np.any(n == 0):
        raise Refused(f"{name}: directions must be finite and non-zero")
    return a / n


def op_gonio(args, out):
    """A gonioreflectometer: a large plane (normal +z) with the material, a sun of angle 0 towards
    wi, an orthographic camera looking from wo; per pair the mean pixel, f(wi, wo) (n.wi) E."""
    wi = directions([p[0] for p in args["pairs"]], "wi")
    wo = directions([p[1] for p in args["pairs"]], "wo")
    size = int(args.get("size", 4))
    reset()
    sc = cycles_scene(size, size, int(args.get("spp", 1)))
    bpy.ops.mesh.primitive_plane_add(size=1000.0)
    plane = bpy.context.active_object
    plane.data.materials.append(material_of(args))
    sun = add_sun(sc, args.get("irradiance", 1.0))
    cam = add_camera(sc, 0.01)  # a 1 cm window on the plane, far from its edges at any angle
    values = np.zeros((len(wi), 3), np.float32)
    for k in range(len(wi)):
        if wi[k, 2] <= 0 or wo[k, 2] <= 0:
            values[k] = np.nan  # below the horizon: no reflection to measure
            continue
        point_towards(sun, wi[k])
        point_towards(cam, wo[k])
        cam.location = Vector(wo[k]) * 10.0
        values[k] = render_rgb(sc, os.path.join(out, "gonio.exr")).reshape(-1, 3).mean(0)
    np.save(os.path.join(out, "values.npy"), values)
    return {"values": "values.npy"}


def op_sphere(args, out):
    """The docs/validation.md#validation-rendering framing: a unit sphere (a Cycles point primitive, an exact sphere) at the origin,
    an orthographic camera on +z looking down -z with +y up covering [-1, 1]^2, one sun per image."""
    lights = directions(args["lights"], "lights")
    size = int(args["size"])
    reset()
    sc = cycles_scene(size, size, int(args.get("spp", 4)))
    mat = material_of(args)
    mesh = bpy.data.meshes.new("anchor")
    mesh.from_pydata([(0.0, 0.0, 0.0)], [], [])
    ball = bpy.data.objects.new("ball", mesh)
    sc.collection.objects.link(ball)
    tree = bpy.data.node_groups.new("unit sphere", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    points = tree.nodes.new("GeometryNodePoints")
    points.inputs["Count"].default_value = 1
    points.inputs["Radius"].default_value = 1.0
    setmat = tree.nodes.new("GeometryNodeSetMaterial")
    setmat.inputs["Material"].default_value = mat
    output = tree.nodes.new("NodeGroupOutput")
    tree.links.new(points.outputs["Points"], setmat.inputs["Geometry"])
    tree.links.new(setmat.outputs["Geometry"], output.inputs["Geometry"])
    ball.modifiers.new("unit sphere", "NODES").node_group = tree
    sun = add_sun(sc, args.get("irradiance", 1.0))
    cam = add_camera(sc, 2.0)
    cam.location = (0.0, 0.0, 5.0)
    cam.rotation_quaternion = (1.0, 0.0, 0.0, 0.0)  # looking down -z, +y up (to_track_quat turns it)
    images = np.zeros((len(lights), size, size, 3), np.float32)
    for k, d in enumerate(lights):
        point_towards(sun, d)
        sc.cycles.seed = int(args.get("seed", 0))
        images[k] = render_rgb(sc, os.path.join(out, "sphere.exr"))
    np.save(os.path.join(out, "images.npy"), images)
    return {"images": "images.npy"}


def op_blend(args, out):
    """A .blend file: a smooth UV sphere with the material, a camera and a sun, Cycles as engine."""
    reset()
    sc = cycles_scene(512, 512, 64)
    sc.cycles.max_bounces = 12
    bpy.data.worlds["black"].node_tree.nodes["Background"].inputs["Strength"].default_value = 0.2
    name = str(args.get("name") or "brdffit")
    mat = principled_material(args["material"], name)
    # extras as JSON text: ID properties take no None and no mixed lists
    mat["brdffit"] = json.dumps(args.get("extras") or {}, sort_keys=True)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=96, ring_count=48, radius=1.0)
    ball = bpy.context.active_object
    ball.name = name
    bpy.ops.object.shade_smooth()
    ball.data.materials.append(mat)
    cam = add_camera(sc, 2.2)
    cam.location = (0.0, -5.0, 0.0)
    point_towards(cam, (0.0, -1.0, 0.0))
    sun = add_sun(sc, 3.0)
    point_towards(sun, (0.4, -0.6, 0.7))
    path = os.path.join(out, "material.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path, compress=False)
    return {"blend": "material.blend"}


def op_blend_maps(args, out):
    """A .blend file of parameter maps: a square in the z = 0 plane facing +z (the maps' aspect, the
    longer side 2 units; texture coordinates with image row 0 at the top, Blender's v running up) with
    the Principled BSDF of ``material``, its inputs in ``textures`` fed by image textures (``Closest``,
    packed into the file; a scalar map through its red channel: a colour-to-float link would take the
    luminance), an orthographic camera above it at one pixel per texel, a sun; Cycles as engine."""
    reset()
    width, height = int(args["width"]), int(args["height"])
    sc = cycles_scene(width, height, 64)
    sc.cycles.max_bounces = 12
    bpy.data.worlds["black"].node_tree.nodes["Background"].inputs["Strength"].default_value = 0.2
    name = str(args.get("name") or "brdffit")
    mat = principled_material(args["material"], name)
    mat["brdffit"] = json.dumps(args.get("extras") or {}, sort_keys=True)
    tree = mat.node_tree
    bsdf = tree.nodes["Principled BSDF"]
    for socket, tex in args["textures"].items():
        if socket not in SOCKETS:
            raise Refused(f"unknown Principled BSDF input {socket!r}; known: {', '.join(SOCKETS)}")
        image = bpy.data.images.load(tex["path"], check_existing=False)
        image.name = tex["name"]
        image.colorspace_settings.name = "Non-Color" if tex["data"] else "Linear Rec.709"
        image.pack()
        node = tree.nodes.new("ShaderNodeTexImage")
        node.image, node.interpolation, node.label = image, "Closest", tex["name"]
        output = node.outputs["Color"]
        if tex["scalar"]:
            split = tree.nodes.new("ShaderNodeSeparateColor")
            tree.links.new(output, split.inputs["Color"])
            output = split.outputs["Red"]
        tree.links.new(output, bsdf.inputs[socket])
    a, b = width / max(width, height), height / max(width, height)
    corners = [(-a, -b, 0.0), (a, -b, 0.0), (a, b, 0.0), (-a, b, 0.0)]
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(corners, [], [(0, 1, 2, 3)])
    uv = mesh.uv_layers.new(name="UVMap")
    for loop in mesh.loops:
        x, y, _ = corners[loop.vertex_index]
        uv.data[loop.index].uv = ((x + a) / (2 * a), (y + b) / (2 * b))
    mesh.materials.append(mat)
    square = bpy.data.objects.new(name, mesh)
    sc.collection.objects.link(square)
    cam = add_camera(sc, 2.0 * max(a, b))
    cam.location = (0.0, 0.0, 5.0)
    cam.rotation_quaternion = (1.0, 0.0, 0.0, 0.0)  # looking down -z, +y up
    point_towards(add_sun(sc, 3.0), (0.4, -0.6, 0.7))
    path = os.path.join(out, "maps.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path, compress=False)
    return {"blend": "maps.blend"}


def op_render_file(args, out):
    """A .blend file rendered through its own camera at its own resolution, direct light only, a black
    world, its one sun turned towards ``light`` with ``irradiance``: a pixel is f (n.l) E."""
    bpy.ops.wm.open_mainfile(filepath=args["path"])
    sc = bpy.context.scene
    suns = [o for o in sc.objects if o.type == "LIGHT" and o.data.type == "SUN"]
    if len(suns) != 1 or sc.camera is None:
        raise Refused(f"{args['path']}: needs one sun and a camera, has {len(suns)} sun(s)")
    sc = cycles_scene(sc.render.resolution_x, sc.render.resolution_y, int(args.get("spp", 4)))
    suns[0].data.energy, suns[0].data.angle = float(args.get("irradiance", 1.0)), 0.0
    point_towards(suns[0], directions([args["light"]], "light")[0])
    np.save(os.path.join(out, "image.npy"), render_rgb(sc, os.path.join(out, "render.exr")))
    return {"image": "image.npy"}


def socket_value(socket):
    v = socket.default_value
    return [float(x) for x in v][:3] if hasattr(v, "__len__") else float(v)


def op_inspect(args, out):
    """The Principled BSDF materials of a .blend file, or of a glTF file imported by Blender's own
    glTF importer: {material: {"distribution", "inputs", "properties", "users"}}."""
    path = args["path"]
    if path.lower().endswith(".blend"):
        bpy.ops.wm.open_mainfile(filepath=path)
    else:
        reset()
        bpy.ops.import_scene.gltf(filepath=path)
    materials = {}
    for mat in bpy.data.materials:
        if not mat.node_tree:
            continue
        for node in mat.node_tree.nodes:
            if node.type == "BSDF_PRINCIPLED":
                materials[mat.name] = {
                    "distribution": node.distribution,
                    "inputs": {k: socket_value(node.inputs[k]) for k in REPORTED},
                    "properties": {k: mat[k] for k in mat.keys() if isinstance(mat[k], (str, int, float))},
                    "users": sorted(o.name for o in bpy.data.objects
                                    if o.type == "MESH" and mat.name in [m.name for m in o.data.materials if m]),
                }
    return {"materials": materials}


OPS = {"gonio": op_gonio, "sphere": op_sphere, "blend": op_blend, "inspect": op_inspect,
       "blend_maps": op_blend_maps, "render_file": op_render_file,
       "ping": lambda args, out: {"blender": bpy.app.version_string}}


def reply(obj):
    _PROTO.write(json.dumps(obj) + "\n")
    _PROTO.flush()


def main():
    reply({"ready": True, "blender": bpy.app.version_string})
    for line in sys.stdin:
        if not line.strip():
            continue
        rid = None
        try:
            req = json.loads(line)
            rid = req.get("id")
            if req.get("op") == "quit":
                reply({"id": rid, "ok": True, "result": {}})
                break
            if req.get("op") not in OPS:
                raise Refused(f"unknown operation {req.get('op')!r}; known: {', '.join(sorted(OPS))}")
            result = OPS[req["op"]](req.get("args", {}), req.get("out") or ".")
            reply({"id": rid, "ok": True, "result": result})
        except Refused as exc:
            reply({"id": rid, "ok": False, "error": str(exc)})
        except Exception as exc:  # the worker survives; the traceback goes to its log (stderr)
            traceback.print_exc()
            reply({"id": rid, "ok": False, "error": f"{type(exc).__name__}: {exc}".splitlines()[0]})


if __name__ == "__main__":
    main()
