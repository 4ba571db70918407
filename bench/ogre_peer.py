"""The Ogre 14 peer of bench/peers.py. Runs INSIDE bench/.peers/ogre-venv (Python 3.12 with the
PyPI packages ogre-python and numpy), started by bench/peers.py as a subprocess:

    bench/.peers/ogre-venv/bin/python bench/ogre_peer.py SCENE.npz OUT_DIR

SCENE.npz (written by peers.py) holds the lights (id, type, position, radius, direction,
outer_angle, inner_angle), the objects (id, bounds_min, bounds_max), one camera, the light
positions of every frame ``frame_positions[F, L, 3]``, and ``warmup``, ``extra_frames``,
``cast_shadows``, ``max_lights`` (K), ``width``, ``height``. This script builds the same scene in Ogre:

- the software "Tiny" render system and a TinyWindow of width x height pixels (an image in
  memory: no display is needed);
- point lights with attenuation range = radius, spot lights with Ogre's *full* cone angles
  2 * outer_angle / 2 * inner_angle, the sun as a directional light; each on its own
  SceneNode (position, direction = the node's -Z); castShadows off on every light (unless
  ``cast_shadows``: Ogre's default, on, which peers.py runs once to show it unsorts the lists);
- every object a ManualObject box with exactly its bounds, on a SceneNode at the box centre,
  so that Ogre's bounding radius is the box's half-diagonal (DESIGN's R);
- a camera with the scene camera's position, frame (r, u, -f), fov_y, aspect, near, far.

Per frame it times (time.perf_counter; ``frame_cpu`` is the process CPU time of the same
span, which tells a frame slowed by other jobs on the machine): ``update`` (set every point/spot light's node
position from Python), ``render`` (``Root.renderOneFrame``: scene graph, culling, the
lights affecting the frustum, software rasterisation) and ``query``
(``MovableObject.queryLights()`` on every object, a Python loop; the lists are built here:
a second call in the same frame returns the cached list at the cost of a bare call). On
the first ``extra_frames`` timed frames, outside the frame time, it also times ``rebuild``
(``SceneManager._notifyLightsDirty()`` then ``queryLights()`` on every object: Ogre's list
building for all N objects on its own) and ``calls`` (a trivial binding call,
``getLightMask()``, on every object: the Python-to-C++ call cost inside ``query``).

After the last frame it reads every object's light list. ogre-python does not wrap
``Ogre::LightList`` (a ``std::vector<Light*>``; queryLights returns an opaque pointer), so
the vector's begin/end pointers are read with ctypes and each ``Light*`` is mapped back to a
light id through the lights' own SWIG pointers.

Writes OUT_DIR/result.json ({"ok": true, ...timings...} or {"ok": false, "stage", "error"})
and OUT_DIR/lists.npz (per object, in the input's object order: ``light_ids[N, K]`` the first
K non-directional lights of Ogre's list, -1 padded; ``listed[N]`` the number of
non-directional lights in it; ``dir_first[N]`` whether the directional lights come first;
``frustum_ids`` the lights of ``_getLightsAffectingFrustum()``).
"""

from __future__ import annotations

import ctypes
import json
import os
import sys
import time
import traceback
from pathlib import Path

import numpy as np

POINT, SPOT, DIRECTIONAL = 0, 1, 2
STAGE = "start"
# Every Ogre object stays referenced until os._exit: letting Python destroy them (Root
# first, in no particular order) crashes with SIGSEGV.
KEEP: list = []


def stage(name: str) -> None:
    global STAGE
    STAGE = name


def read_light_list(ptr: int, ids: dict[int, int]) -> list[int]:
    """The light ids in the std::vector<Light*> at address ``ptr`` (libstdc++ layout:
    begin, end, capacity pointers)."""
    begin = ctypes.c_void_p.from_address(ptr).value or 0
    end = ctypes.c_void_p.from_address(ptr + 8).value or 0
    n = (end - begin) // 8
    if n <= 0:
        return []
    return [ids[a] for a in (ctypes.c_void_p * n).from_address(begin)]


def box(mo, half: np.ndarray, material: str, Ogre) -> None:
    """A closed box of half-extents ``half`` centred on the local origin."""
    hx, hy, hz = (float(v) for v in half)
    mo.begin(material, Ogre.RenderOperation.OT_TRIANGLE_LIST)
    for sx in (-1.0, 1.0):
        for sy in (-1.0, 1.0):
            for sz in (-1.0, 1.0):
                mo.position(sx * hx, sy * hy, sz * hz)
                mo.normal(sx * 0.57735, sy * 0.57735, sz * 0.57735)
                mo.textureCoord(0.5, 0.5)
    # vertex index = 4 * ix + 2 * iy + iz; faces wound counter-clockwise seen from outside
    for a, b, c in ((0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1),
                    (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)):
        mo.triangle(a, b, c)
    mo.end()


def run(scene_path: Path, out: Path) -> dict:
    stage("read scene")
    z = np.load(scene_path)
    lid, ltype = z["light_id"], z["light_type"]
    lpos, lrad, ldir = z["light_position"], z["light_radius"], z["light_direction"]
    louter, linner = z["light_outer_angle"], z["light_inner_angle"]
    oid, lo, hi = z["object_id"], z["bounds_min"], z["bounds_max"]
    frames = z["frame_positions"]
    warmup, k, extra = int(z["warmup"]), int(z["max_lights"]), int(z["extra_frames"])
    cast_shadows = bool(z["cast_shadows"])
    width, height = int(z["width"]), int(z["height"])
    cam_pos, cam_fwd, cam_up = z["camera_position"], z["camera_forward"], z["camera_up"]
    fov_y, aspect, near, far = (float(z[n]) for n in ("camera_fov_y", "camera_aspect",
                                                      "camera_near", "camera_far"))

    stage("import Ogre")
    import Ogre

    base = os.path.dirname(Ogre.__file__)
    info: dict = {"ogre_version": Ogre.__version__, "python": sys.version.split()[0]}

    stage("load libSDL2 (RenderSystem_Tiny links it; the wheel keeps it one folder up)")
    ctypes.CDLL(os.path.join(base, "libSDL2-2.0.so.0"), mode=ctypes.RTLD_GLOBAL)

    stage("create Root and log")
    lm = Ogre.LogManager()
    lm.createLog(str(out / "ogre.log"), True, False, False)
    root = Ogre.Root("", "", "")
    KEEP.extend([lm, root])

    stage("load plugin RenderSystem_Tiny")
    root.loadPlugin(os.path.join(base, "OGRE", "RenderSystem_Tiny"))
    stage("select Tiny render system")
    rs = root.getRenderSystemByName("Tiny Rendering Subsystem")
    if rs is None:
        raise RuntimeError("no 'Tiny Rendering Subsystem' after loading RenderSystem_Tiny")
    root.setRenderSystem(rs)
    root.initialise(False)
    stage("create TinyWindow")
    win = root.createRenderWindow("lightsched-peer", width, height, False)
    KEEP.append(win)
    info["render_system"] = rs.getName()
    info["window"] = [win.getWidth(), win.getHeight()]

    t_setup = time.perf_counter()
    stage("build scene")
    sm = root.createSceneManager()
    sm.setAmbientLight(Ogre.ColourValue(0.1, 0.1, 0.1))
    rootnode = sm.getRootSceneNode()
    light_nodes: list = []
    objs: list = []
    KEEP.extend([sm, light_nodes, objs])

    # Tiny's default shader samples texture unit 0 whenever it holds an image pointer; with
    # only untextured materials (BaseWhite) nothing ever binds or clears it, and the
    # rasteriser dies of SIGFPE (an integer modulo by a zero image size, seen in gdb).
    # A 2x2 white texture avoids it.
    img = Ogre.Image()
    img.create(Ogre.PF_BYTE_RGBA, 2, 2)
    img.setTo(Ogre.ColourValue(1, 1, 1, 1))
    Ogre.TextureManager.getSingleton().loadImage("peer_white", "General", img)
    mat = Ogre.MaterialManager.getSingleton().create("PeerLit", "General")
    ps = mat.getTechnique(0).getPass(0)
    ps.createTextureUnitState("peer_white")
    ps.setLightingEnabled(True)
    mat.load()

    cam = sm.createCamera("cam")
    cnode = rootnode.createChildSceneNode()
    cnode.attachObject(cam)
    KEEP.extend([img, mat, cam, cnode])
    f = cam_fwd / np.linalg.norm(cam_fwd)
    r = np.cross(f, cam_up)
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    cnode.setPosition(*(float(v) for v in cam_pos))
    cnode.setOrientation(Ogre.Quaternion(Ogre.Vector3(*r.tolist()), Ogre.Vector3(*u.tolist()),
                                         Ogre.Vector3(*(-f).tolist())))
    win.addViewport(cam)
    cam.setFOVy(Ogre.Radian(fov_y))
    cam.setAspectRatio(aspect)
    cam.setNearClipDistance(near)
    cam.setFarClipDistance(far)

    moving = []
    ptr_to_id: dict[int, int] = {}
    for i in range(lid.size):
        t = int(ltype[i])
        light = sm.createLight(f"L{int(lid[i])}")
        light.setType({POINT: Ogre.Light.LT_POINT, SPOT: Ogre.Light.LT_SPOTLIGHT,
                       DIRECTIONAL: Ogre.Light.LT_DIRECTIONAL}[t])
        light.setCastShadows(cast_shadows)
        light.setDiffuseColour(Ogre.ColourValue(1, 1, 1))
        if t != DIRECTIONAL:
            light.setAttenuation(float(lrad[i]), 1.0, 0.0, 0.0)
        if t == SPOT:
            light.setSpotlightRange(Ogre.Radian(2.0 * float(linner[i])),
                                    Ogre.Radian(2.0 * float(louter[i])))
        node = rootnode.createChildSceneNode()
        node.attachObject(light)
        if t != DIRECTIONAL:
            node.setPosition(*(float(v) for v in lpos[i]))
            moving.append(i)
        if t != POINT:
            node.setDirection(Ogre.Vector3(*(float(v) for v in ldir[i])), Ogre.Node.TS_WORLD)
        light_nodes.append(node)
        ptr_to_id[int(light.this)] = int(lid[i])
    is_dir = {int(lid[i]) for i in range(lid.size) if int(ltype[i]) == DIRECTIONAL}

    centre = 0.5 * (lo + hi)
    half = 0.5 * (hi - lo)
    for j in range(oid.size):
        mo = sm.createManualObject(f"O{int(oid[j])}")
        box(mo, half[j], "PeerLit", Ogre)
        mo.setCastShadows(False)
        node = rootnode.createChildSceneNode()
        node.setPosition(*(float(v) for v in centre[j]))
        node.attachObject(mo)
        objs.append(mo)
    info["setup_s"] = time.perf_counter() - t_setup
    if objs:
        j = int(np.argmax(np.linalg.norm(half, axis=1)))
        info["bounding_radius_check"] = [float(objs[j].getBoundingRadius()),
                                         float(np.linalg.norm(half[j]))]

    stage("frames")
    move_nodes = [light_nodes[i] for i in moving]
    rows: list[dict[str, float]] = []
    for fi in range(frames.shape[0]):
        pos = frames[fi][moving].tolist()
        c0 = time.process_time()
        t0 = time.perf_counter()
        for node, (x, y, zz) in zip(move_nodes, pos, strict=True):
            node.setPosition(x, y, zz)
        t1 = time.perf_counter()
        root.renderOneFrame()
        t2 = time.perf_counter()
        for mo in objs:
            mo.queryLights()
        t3 = time.perf_counter()
        c3 = time.process_time()
        if fi < warmup:
            print("PROGRESS", fi, flush=True)
            continue
        row = {"update": t1 - t0, "render": t2 - t1, "query": t3 - t2, "frame": t3 - t0,
               "frame_cpu": c3 - c0}
        if fi - warmup < extra:
            t3 = time.perf_counter()
            sm._notifyLightsDirty()
            for mo in objs:
                mo.queryLights()
            t4 = time.perf_counter()
            for mo in objs:
                mo.getLightMask()
            row.update(rebuild=t4 - t3, calls=time.perf_counter() - t4)
        rows.append(row)
        print("PROGRESS", fi, flush=True)

    stage("read light lists")
    n = oid.size
    ids = np.full((n, k), -1, np.int32)
    listed = np.zeros(n, np.int32)
    dir_first = np.ones(n, bool)
    for j, mo in enumerate(objs):
        lst = read_light_list(int(mo.queryLights()), ptr_to_id)
        rest = [x for x in lst if x not in is_dir]
        nd = len(lst) - len(rest)
        dir_first[j] = all(x in is_dir for x in lst[:nd])
        listed[j] = len(rest)
        ids[j, :min(k, len(rest))] = rest[:k]
    frustum = np.array(read_light_list(int(sm._getLightsAffectingFrustum()), ptr_to_id),
                       np.int32)
    np.savez(out / "lists.npz", light_ids=ids, listed=listed, dir_first=dir_first,
             frustum_ids=frustum)
    info["frames"] = rows
    info["n_objects"], info["n_lights"] = int(n), int(lid.size)
    info["omp_num_threads"] = os.environ.get("OMP_NUM_THREADS", "")
    return info


def main() -> int:
    scene_path, out = Path(sys.argv[1]), Path(sys.argv[2])
    try:
        info = run(scene_path, out)
        info["ok"] = True
    except BaseException as e:  # report every failure, with the step it happened in
        info = {"ok": False, "stage": STAGE, "error": f"{type(e).__name__}: {e}",
                "traceback": traceback.format_exc()}
    (out / "result.json").write_text(json.dumps(info))
    sys.stdout.flush()
    sys.stderr.flush()
    # Ogre's teardown at interpreter exit crashes (SIGSEGV) with the SWIG objects still
    # alive; the results are written, so leave without it.
    os._exit(0 if info["ok"] else 2)


if __name__ == "__main__":
    main()
