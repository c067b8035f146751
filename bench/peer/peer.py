#!/usr/bin/env python3
"""Peer benchmark: tress against Mitsuba 3 (llvm_ad_rgb) on the same hair scenes.

Run through `bench/peer/run.sh`, which makes the virtualenv and builds tress. For every
benchmark scene it renders, in alternating rounds, tress (tubes and ribbons) and Mitsuba
(`linearcurve`, and the frame-correct `bsplinecurve` setup where affordable) at equal spp, and
prints render-only and whole-process time, the noise of each image against the renderer's own
converged image, and the time each needs to reach the same error. A second table compares the
converged images of the two renderers (mean radiance over the hair), with tress's default
`overlaps: PassThrough` (Mitsuba's convention where fibers interpenetrate) and `Scatter`. All
of it under a white constant sky and under the Venice map (`--light`). See README.md.
"""

import argparse
import csv
import hashlib
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

MITSUBA_VERSION = "3.9.1"
# Chiang parameters shared by both renderers (tress's defaults; Mitsuba's `hair` is told the
# same explicitly: its ext_ior defaults to air, 1.000277, not vacuum).
SIGMA_A = (0.25, 0.5, 1.2)
BETA_M = BETA_N = 0.3
ALPHA_DEG = 2.0
ETA = 1.55
# tress counts scattering events (max_depth 64), Mitsuba path vertices including the camera
# (max_depth 65 = 64 scattering events).
TRESS_MAX_DEPTH = 64
RR_DEPTH = 5
# relMSE = mean((x − ref)² / (ref² + EPS)) over pixels and channels.
REL_EPS = 1e-2
# The Venice map (shared data) and its rotation about +y for tress: with −60° its sun, 3° above
# the horizon, lies 96° to the right of straight.hair's view direction (−z), so the hair is lit
# from one side and a mirrored or turned map shows. Mitsuba's `envmap` is the same map with
# `to_world` = rotate_y(rotation + 180°) (Mitsuba puts u = 0 at local −z, tress u = 0.5 at −z
# turned by its rotation), no mirror: `envmap_check` prints the agreement.
VENICE_FILE = Path("envmaps") / "venice_sunset_1k.hdr"
VENICE_ROTATION = -60.0


class Light:
    """The light of a run, written for both renderers."""

    def __init__(self, name, data):
        self.name = name
        if name == "sky":
            self.label = "white constant sky"
            self.map = None
        else:
            self.label = f"Venice map ({VENICE_FILE.name}, rotation {VENICE_ROTATION:g}°)"
            self.map = (data / VENICE_FILE).resolve()
            if not self.map.exists():
                sys.exit(f"{self.map} is missing: pass --data DIR (the shared data set)")

    def tress_ron(self):
        if self.map is None:
            return "Constant(radiance: (1.0, 1.0, 1.0))"
        return f'Environment(file: "{self.map}", rotation: {VENICE_ROTATION}, scale: 1.0)'

    def mitsuba_desc(self):
        if self.map is None:
            return {"type": "constant"}
        return {"type": "envmap", "file": str(self.map), "rotation": VENICE_ROTATION}

    def key(self):
        return [self.name, str(self.map), VENICE_ROTATION if self.map else None]


# ---------------------------------------------------------------------------------------------
# Geometry: strands as (points, radius) arrays, written once for both renderers.


def read_cyhair(path):
    """Cem Yuksel's .hair with a points array and default segments/thickness (straight.hair),
    converted from z-up to y-up as tress's reader does: (x, y, z) → (x, z, −y)."""
    data = Path(path).read_bytes()
    if data[:4] != b"HAIR":
        sys.exit(f"{path}: not a HAIR file")
    strands, points, flags, segments = np.frombuffer(data[4:20], "<u4")
    thickness = float(np.frombuffer(data[20:24], "<f4")[0])
    if flags & 0b101 or not flags & 0b10:
        sys.exit(f"{path}: only files without segment and thickness arrays are read here")
    p = np.frombuffer(data[128 : 128 + 12 * int(points)], "<f4").reshape(-1, 3)
    p = np.stack([p[:, 0], p[:, 2], -p[:, 1]], axis=1)
    return p.reshape(int(strands), int(segments) + 1, 3), 0.5 * thickness


def write_cyhair(path, strands, radius):
    """A .hair file of equal-length strands (points array, default segments and thickness),
    stored as given (tress reads it with z_up: false)."""
    n, m, _ = strands.shape
    header = bytearray(128)
    header[:4] = b"HAIR"
    header[4:20] = np.array([n, n * m, 0b10, m - 1], "<u4").tobytes()
    header[20:36] = np.array([2 * radius, 1.0, 1.0, 1.0], "<f4").tobytes()
    with open(path, "wb") as f:
        f.write(header)
        f.write(strands.astype("<f4").tobytes())


def write_mitsuba_curves(path, strands, radius, triple):
    """Mitsuba's curve text format: `x y z r` per control point, a blank line between curves.
    `triple` repeats every point three times: a uniform cubic B-spline through a triple point
    passes through it, and between two triple points it is the straight segment, so
    `bsplinecurve` then draws exactly the polyline `linearcurve` draws (with the sphere joints
    of a sweep), but with a curve frame (see README.md)."""
    pts = np.repeat(strands, 3, axis=1) if triple else strands
    n, m, _ = pts.shape
    rows = np.concatenate([pts.reshape(-1, 3), np.full((n * m, 1), radius)], axis=1)
    lines = np.char.mod("%.9g", rows)
    text = np.char.add(np.char.add(np.char.add(lines[:, 0], " "), np.char.add(lines[:, 1], " ")),
                       np.char.add(np.char.add(lines[:, 2], " "), lines[:, 3]))
    with open(path, "w") as f:
        for i in range(n):
            f.write("\n".join(text[i * m : (i + 1) * m]))
            f.write("\n\n")


def slab(rng):
    """A dense slab of straight fibers that do not touch: twelve layers of parallel fibers
    along x, 2.2–2.6 radii apart within a layer and 2.2 radii between layers, staggered."""
    r = 0.01
    strands = []
    for k in range(12):
        z = -2.2 * r * k
        y = -1.0 + 1.3 * r * (k % 2)
        while y < 1.0:
            x0 = -1.0 + 0.2 * rng.random()
            strands.append(np.linspace([x0, y, z], [x0 + 1.8, y, z], 4))
            y += 2.2 * r + 0.4 * r * rng.random()
    return np.array(strands), r


def wavy_groom(n, rng, segments=32):
    """`n` wavy strands on a spherical scalp (radius 1, strands 1.6 long ± 15 %, fiber radius
    0.004: the proportions of tress's procedural hair), combed back and down, resting on a
    layer above the scalp and hanging below its equator, with a sideways wave that advances
    with height so that neighbours wave together."""
    m = segments + 1
    up = np.array([0.0, 1.0, -0.5]) / np.sqrt(1.25)
    cos_t = 1.0 - rng.random(n) * (1.0 - np.cos(np.radians(75.0)))
    sin_t = np.sqrt(1.0 - cos_t**2)
    phi = 2 * np.pi * rng.random(n)
    a = np.cross(up, [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(up, a)
    normal = (sin_t * np.cos(phi))[:, None] * a + (sin_t * np.sin(phi))[:, None] * b \
        + cos_t[:, None] * up
    layer = 1.003 + 0.06 * rng.random(n)
    length = 1.6 * (0.85 + 0.3 * rng.random(n))
    ds = length / segments
    flow = np.array([0.0, -0.5, -1.0]) / np.sqrt(1.25)
    comb = flow - normal * (normal @ flow)[:, None]
    comb /= np.linalg.norm(comb, axis=1, keepdims=True)
    d = 0.15 * normal + comb + 0.1 * rng.normal(size=(n, 3)) / np.sqrt(3)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    pts = np.empty((n, m, 3))
    pts[:, 0] = normal
    gravity = np.array([0.0, -5.0 / 1.6, 0.0])
    for k in range(1, m):
        d = d + gravity * ds[:, None]
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        q = pts[:, k - 1] + d * ds[:, None]
        dist = np.linalg.norm(q, axis=1)
        onto = (dist < layer) | (q[:, 1] > 0.0)
        q[onto] *= (layer[onto] / dist[onto])[:, None]
        d = q - pts[:, k - 1]
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        pts[:, k] = q
    # The wave: sideways (across the strand, horizontal), faded in over the first 15 %.
    tangent = np.gradient(pts, axis=1)
    side = np.cross(tangent, [0.0, 1.0, 0.0])
    side /= np.maximum(np.linalg.norm(side, axis=2, keepdims=True), 1e-6)
    s = np.linspace(0.0, 1.0, m)[None, :]
    ramp = np.clip(s / 0.15, 0.0, 1.0) ** 2 * (3 - 2 * np.clip(s / 0.15, 0.0, 1.0))
    amp = 0.05 * (0.8 + 0.4 * rng.random(n))[:, None]
    angle = 2 * np.pi * 3.0 * (1.0 - pts[:, :, 1]) + 0.5 * rng.random(n)[:, None]
    pts += (ramp * amp * np.sin(angle))[:, :, None] * side
    return pts, 0.004


# ---------------------------------------------------------------------------------------------
# Scenes


class Scene:
    """One geometry and camera, rendered by both."""

    def __init__(self, name, label, hair_file, z_up, curves, camera, radius_scale=1.0):
        self.name, self.label = name, label
        self.hair_file, self.z_up = hair_file, z_up
        self.curves = curves  # {"linear": path, "bspline": path (where affordable)}
        self.camera = camera  # (look_from, look_at, fov)
        # tress scales the file's radii; Mitsuba's curve files are written scaled.
        self.radius_scale = radius_scale

    def tress_ron(self, curve, overlaps, res, light):
        (f, a, fov) = self.camera
        vec = lambda v: "({:.6g}, {:.6g}, {:.6g})".format(*v)
        return f"""(
    camera: (look_from: {vec(f)}, look_at: {vec(a)}, fov: {fov}),
    film: (width: {res}, height: {res}, spp: 1, seed: 1),
    integrator: Path(max_depth: {TRESS_MAX_DEPTH}, rr_depth: {RR_DEPTH}),
    materials: {{
        "hair": Hair(Chiang(beta_m: {BETA_M}, beta_n: {BETA_N}, alpha: {ALPHA_DEG}, eta: {ETA},
                            pigment: SigmaA{vec(SIGMA_A)})),
    }},
    objects: [
        Hair(source: Hair(path: "{self.hair_file}", z_up: {str(self.z_up).lower()}),
             material: "hair",
             options: (curve: {curve}, overlaps: {overlaps}, radius_scale: {self.radius_scale})),
    ],
    lights: [{light.tress_ron()}],
)
"""

    def mitsuba_desc(self, kind, res, light):
        (f, a, fov) = self.camera
        return {
            "curves": str(self.curves[kind]), "kind": f"{kind}curve",
            "look_from": list(f), "look_at": list(a),
            "fov": fov, "res": res, "light": light.mitsuba_desc(),
        }


def build_scenes(work, data, quick):
    rng = np.random.default_rng(1)
    scenes = {}
    geo = work / "geometry"
    geo.mkdir(parents=True, exist_ok=True)

    def curves(name, strands, r, bspline):
        out = {}
        for kind, triple in [("linear", False), ("bspline", True)]:
            if kind == "bspline" and not bspline:
                continue
            path = geo / f"{name}.{kind}.txt"
            if not path.exists():
                tmp = path.with_suffix(".tmp")
                write_mitsuba_curves(tmp, strands, r, triple)
                tmp.replace(path)
            out[kind] = path
        return out

    straight_path = data / "hair" / "straight.hair"
    if not straight_path.exists():
        sys.exit(f"{straight_path} is missing: pass --data DIR (the shared data set)")
    strands, r = read_cyhair(straight_path)
    camera = ((0, 25, 150), (0, 22, 0), 40.0)
    scenes["straight"] = Scene("straight", "straight.hair (10k strands)", straight_path, True,
                               curves("straight", strands, r, True), camera)
    scenes["straight_half"] = Scene("straight_half", "straight.hair, half radius", straight_path,
                                    True, curves("straight_half", strands, 0.5 * r, True),
                                    camera, radius_scale=0.5)

    strands, r = slab(rng)
    path = geo / "slab.hair"
    write_cyhair(path, strands, r)
    scenes["slab"] = Scene("slab", "slab of fibers that do not touch", path, False,
                           curves("slab", strands, r, True), ((0, 0.8, 3.5), (0, 0, 0), 40.0))

    n = 10_000 if quick else 100_000
    path = geo / f"groom{n}.hair"
    if not path.exists():
        strands, r = wavy_groom(n, rng)
        write_cyhair(path, strands, r)
        groom_curves = curves(f"groom{n}", strands, r, False)
    else:
        groom_curves = {"linear": geo / f"groom{n}.linear.txt"}
        if not groom_curves["linear"].exists():
            sys.exit(f"{groom_curves['linear']} is missing: delete {path} to regenerate")
    scenes["groom"] = Scene("groom", f"wavy groom ({n // 1000}k strands × 32 segments)", path,
                            False, groom_curves, ((3.2, 0.9, -2.6), (0, -0.5, -0.4), 40.0))
    return scenes


# ---------------------------------------------------------------------------------------------
# Rendering


def mitsuba_light(mi, light):
    """Mitsuba's emitter for a `Light.mitsuba_desc()`."""
    if light["type"] == "constant":
        return {"type": "constant", "radiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}
    return {"type": "envmap", "filename": light["file"],
            "to_world": mi.ScalarTransform4f().rotate(axis=[0, 1, 0],
                                                      angle=light["rotation"] + 180.0)}


def mitsuba_render_main(argv):
    """Child process: one Mitsuba render. Prints a JSON line with the render-only time."""
    import mitsuba as mi
    import drjit as dr

    desc = json.loads(argv[0])
    spp, seed, threads, out = int(argv[1]), int(argv[2]), int(argv[3]), argv[4]
    mi.set_variant("llvm_ad_rgb")
    dr.set_thread_count(threads)
    t0 = time.perf_counter()
    res = desc["res"]
    to_world = mi.ScalarTransform4f().look_at(origin=desc["look_from"], target=desc["look_at"],
                                              up=[0, 1, 0])
    scene = mi.load_dict({
        "type": "scene",
        "sky": mitsuba_light(mi, desc["light"]),
        "integrator": {"type": "path", "max_depth": TRESS_MAX_DEPTH + 1, "rr_depth": RR_DEPTH},
        "sensor": {
            "type": "perspective", "fov": desc["fov"], "fov_axis": "y", "to_world": to_world,
            "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"},
                     "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": spp},
        },
        "hair": {
            "type": desc["kind"], "filename": desc["curves"],
            "bsdf": {"type": "hair", "sigma_a": {"type": "rgb", "value": list(SIGMA_A)},
                     "int_ior": ETA, "ext_ior": 1.0, "longitudinal_roughness": BETA_M,
                     "azimuthal_roughness": BETA_N, "scale_tilt": ALPHA_DEG},
        },
    })
    load_s = time.perf_counter() - t0
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    dr.kernel_history()
    t1 = time.perf_counter()
    image = mi.render(scene, spp=spp, seed=seed)
    dr.eval(image)
    dr.sync_thread()
    wall = time.perf_counter() - t1
    # Kernels compiled during the render (none once Dr.Jit's disk cache holds them) are
    # taken out of the render-only time.
    compile_s = sum(k.get("codegen_time", 0.0) + k.get("backend_time", 0.0)
                    for k in dr.kernel_history()) / 1000.0
    mi.Bitmap(image).write(out)
    print(json.dumps({"render_s": wall - compile_s, "compile_s": compile_s, "load_s": load_s}))


class Renderers:
    def __init__(self, args, work):
        self.args, self.work = args, work
        self.tress = args.tress
        self.threads = args.threads
        (work / "scenes").mkdir(exist_ok=True)
        (work / "images").mkdir(exist_ok=True)

    def tress_scene_file(self, scene, light, curve, overlaps, res):
        """The tress scene file of `scene` with these options, named by its contents."""
        ron = scene.tress_ron(curve, overlaps, res, light)
        path = self.work / "scenes" / (hashlib.sha1(ron.encode()).hexdigest()[:12] + ".ron")
        path.write_text(ron)
        return path

    def tress_render(self, scene, light, curve, overlaps, res, spp, seed, out):
        path = self.tress_scene_file(scene, light, curve, overlaps, res)
        cmd = [str(self.tress), "render", str(path), "--spp", str(spp), "--seed", str(seed),
               "--threads", str(self.threads), "--out", str(out), "--no-preview", "--alpha",
               "--log-format", "json"]
        t0 = time.perf_counter()
        run = subprocess.run(cmd, capture_output=True, text=True)
        whole = time.perf_counter() - t0
        if run.returncode != 0:
            sys.exit(f"tress failed: {' '.join(cmd)}\n{run.stderr}{run.stdout}")
        summary = json.loads(run.stdout.strip().splitlines()[-1])
        return {"render_s": summary["time_s"], "whole_s": whole}

    def mitsuba_render(self, scene, light, kind, res, spp, seed, out):
        desc = json.dumps(scene.mitsuba_desc(kind, res, light))
        cmd = [sys.executable, __file__, "mitsuba-child", desc, str(spp), str(seed),
               str(self.threads), str(out)]
        t0 = time.perf_counter()
        run = subprocess.run(cmd, capture_output=True, text=True)
        whole = time.perf_counter() - t0
        if run.returncode != 0:
            sys.exit(f"Mitsuba failed: {' '.join(cmd[:3])} …\n{run.stderr[-3000:]}")
        summary = json.loads(run.stdout.strip().splitlines()[-1])
        return {"render_s": summary["render_s"], "whole_s": whole,
                "compile_s": summary["compile_s"]}

    def render(self, variant, res, spp, seed, out):
        scene, light, who, shape, extra = variant
        if who == "tress":
            return self.tress_render(scene, light, shape, extra, res, spp, seed, out)
        return self.mitsuba_render(scene, light, shape, res, spp, seed, out)

    def reference(self, variant, res, spp):
        """The variant's converged image, rendered once and kept (keyed by everything that
        shapes it, the tress binary's modification time included)."""
        scene, light, who, shape, extra = variant
        stamp = os.stat(self.tress).st_mtime_ns if who == "tress" else MITSUBA_VERSION
        key = [scene.name, str(scene.hair_file), scene.radius_scale, who, shape, extra, res,
               spp, str(stamp), scene.camera]
        if light.name != "sky":  # the sky's references keep the keys they had
            key.append(light.key())
        key = json.dumps(key)
        out = self.work / "images" / f"ref-{hashlib.sha1(key.encode()).hexdigest()[:16]}.exr"
        if not out.exists():
            print(f"  reference: {label(variant)}, {spp} spp …", flush=True)
            tmp = out.with_name("tmp-" + out.name)
            self.render(variant, res, spp, 1_000_003, tmp)
            tmp.replace(out)
        return read_exr(out)


def label(variant):
    scene, light, who, shape, extra = variant
    if who == "tress":
        name = {"Round": "tubes", "Flat": "ribbons"}[shape]
        if extra != "PassThrough":  # tress's default, Mitsuba's convention
            name += f", {extra}"
    else:
        name = {"linear": "linearcurve", "bspline": "bsplinecurve ×3"}[shape]
    return f"{who} {name}"


def read_exr(path):
    import mitsuba as mi

    channels = dict(mi.Bitmap(str(path)).split())
    img = np.array(channels["<root>"], dtype=np.float64)
    return img


def rel_mse(img, ref):
    return float(np.mean((img[..., :3] - ref[..., :3]) ** 2 / (ref[..., :3] ** 2 + REL_EPS)))


# ---------------------------------------------------------------------------------------------
# The two tables


def timing_table(r, scenes, light, cfg, log):
    """Alternating rounds at equal spp; relMSE against each variant's own reference. Returns
    the table and, per (scene key, tress variant, Mitsuba variant), the render-only time to
    equal error, tress ÷ Mitsuba."""
    rows = []
    equal_error = {}
    for key in ["straight", "groom"]:
        scene = scenes[key]
        variants = [(scene, light, "tress", "Round", cfg.overlaps),
                    (scene, light, "tress", "Flat", cfg.overlaps),
                    (scene, light, "mitsuba", "linear", None)]
        if "bspline" in scene.curves:
            variants.append((scene, light, "mitsuba", "bspline", None))
        refs = {label(v): r.reference(v, cfg.res, cfg.ref_spp) for v in variants}
        side_by_side(r.work / "images" / f"{light.name}-{key}-timed.png", list(refs.values()))
        stats = {label(v): {"render": [], "whole": [], "rel": []} for v in variants}
        print(f"  {scene.label}, {light.label}: {cfg.rounds} alternating rounds of "
              f"{len(variants)} renders", flush=True)
        for k in range(cfg.rounds):
            order = variants if k % 2 == 0 else variants[::-1]
            for v in order:
                out = r.work / "images" / "round.exr"
                t = r.render(v, cfg.res, cfg.spp, 1 + k, out)
                s = stats[label(v)]
                s["render"].append(t["render_s"])
                s["whole"].append(t["whole_s"])
                s["rel"].append(rel_mse(read_exr(out), refs[label(v)]))
        # The reference's own noise adds spp/ref_spp of the image's to the measured relMSE.
        bias = 1.0 + cfg.spp / cfg.ref_spp
        summary = {}
        for name, s in stats.items():
            summary[name] = {
                "render": statistics.median(s["render"]),
                "whole": statistics.median(s["whole"]),
                "rel": statistics.mean(s["rel"]) / bias,
            }
        for name in summary:
            if not name.startswith("tress"):
                continue
            for peer in summary:
                if peer.startswith("tress"):
                    continue
                a, b = summary[name], summary[peer]
                # The load of a shared machine changes between rounds, not within one: the
                # ratio of two renders of the same round, median over the rounds.
                ratio = {kind: statistics.median(
                    x / y for x, y in zip(stats[name][kind], stats[peer][kind]))
                    for kind in ["render", "whole"]}
                noise = a["rel"] / b["rel"]
                equal_error[(key, name, peer)] = ratio["render"] * noise
                rows.append([
                    scene.label, name, peer,
                    f"{a['render']:.2f} / {b['render']:.2f}",
                    f"{ratio['render']:.2f}",
                    f"{ratio['whole']:.2f}",
                    f"{a['rel']:.2e} / {b['rel']:.2e}",
                    f"{1 / noise:.2f}",
                    f"{ratio['render'] * noise:.2f}",
                    f"{ratio['whole'] * noise:.2f}",
                ])
        log(f"\nPer-round figures, {scene.label}, {light.label} (render s, whole s, relMSE):")
        for name, s in stats.items():
            log(f"- {name}: render {fmt_list(s['render'])}; whole {fmt_list(s['whole'])}; "
                f"relMSE {fmt_list(s['rel'], '.2e')}")
    header = ["scene", "tress", "Mitsuba", "render s (median)", "render ÷",
              "whole process ÷", "relMSE per image", "noise: Mitsuba ÷ tress",
              "time to equal error ÷ (render)", "(whole process)"]
    return header, rows, equal_error


def embree_bound_table(r, scenes, light, cfg, equal_error):
    """How far Embree alone is from Mitsuba: `tress bench --scene` renders each tress variant
    and traces the same rays again with Embree alone, each ray leaving a fiber started where it
    leaves it; the ratio of the two rates (per CPU-second) times tress's time to equal error
    is that of a renderer whose only cost is Embree's, on tress's rays."""
    rows = []
    for key in ["straight", "groom"]:
        scene = scenes[key]
        for curve in ["Round", "Flat"]:
            v = (scene, light, "tress", curve, cfg.overlaps)
            path = r.tress_scene_file(scene, light, curve, cfg.overlaps, cfg.res)
            csv_path = r.work / "bench-scene.csv"
            cmd = [str(r.tress), "bench", "--scene", str(path), "--spp", str(cfg.spp),
                   "--threads", str(r.threads), "--csv", str(csv_path)]
            run = subprocess.run(cmd, capture_output=True, text=True)
            if run.returncode != 0:
                sys.exit(f"tress bench failed: {' '.join(cmd)}\n{run.stderr}")
            table = {}
            with open(csv_path, newline="") as f:
                for row in csv.DictReader(f):
                    table[(row["metric"], row["threads"])] = float(row["value"] or "nan")
            threads = str(r.threads)
            rate = table[("path/rays_per_s", threads)]
            past = table[("path/ratio_vs_replay_plain-past-fiber_cpu", threads)]
            plain = table[("path/ratio_vs_replay_plain_cpu", threads)]
            tte = equal_error[(key, label(v), "mitsuba linearcurve")]
            rows.append([scene.label, label(v), f"{rate:.3f}", f"{past:.2f}", f"{plain:.2f}",
                         f"{tte:.2f}", f"{past * tte:.2f}"])
    header = ["scene", "tress", "path Mrays/s", "path ÷ Embree alone (past the fiber)",
              "(÷ Embree alone stopping at the fiber)",
              "time to equal error ÷ Mitsuba linearcurve", "Embree alone on these rays ÷ Mitsuba"]
    return header, rows


def fmt_list(xs, spec=".2f"):
    return ", ".join(format(x, spec) for x in xs)


def hair_mean(img, mask):
    return img[..., :3][mask].mean(axis=0)


def image_table(r, scenes, light, cfg):
    """Converged images: tress (both overlap conventions) against Mitsuba's frame-correct
    setup, mean RGB over the pixels the hair covers fully."""
    rows = []
    for key in ["slab", "straight", "straight_half"]:
        scene = scenes[key]
        mitsuba = r.reference((scene, light, "mitsuba", "bspline", None), cfg.res, cfg.ref_spp)
        tress = {}
        for curve in ["Round", "Flat"]:
            for overlaps in ["PassThrough", "Scatter"]:
                v = (scene, light, "tress", curve, overlaps)
                tress[label(v)] = r.reference(v, cfg.res, cfg.ref_spp)
        mask = next(iter(tress.values()))[..., 3] > 0.999
        base = hair_mean(mitsuba, mask)
        if key == "straight":
            lin = r.reference((scene, light, "mitsuba", "linear", None), cfg.res, cfg.ref_spp)
            rows.append([scene.label, "Mitsuba linearcurve (wrong frame)",
                         *pct(hair_mean(lin, mask), base)])
            side_by_side(r.work / "images" / f"{light.name}-{key}.png",
                         [tress["tress tubes"], tress["tress ribbons"], mitsuba, lin])
        for lab, img in tress.items():
            rows.append([scene.label, lab, *pct(hair_mean(img, mask), base)])
        rows.append([scene.label, "(Mitsuba bsplinecurve ×3: mean RGB)",
                     *(f"{c:.4f}" for c in base)])
    header = ["scene", "image", "R vs Mitsuba", "G", "B"]
    return header, rows


def side_by_side(path, images):
    """A PNG of converged images side by side (sRGB, clipped), to look at."""
    import mitsuba as mi

    row = np.concatenate([img[..., :3] for img in images], axis=1).astype(np.float32)
    mi.Bitmap(row).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.UInt8, True).write(str(path))


def pct(a, b):
    return [f"{100 * (x / y - 1):+.1f} %" for x, y in zip(a, b)]


def frame_check(work, log):
    """The fiber axis Mitsuba's `hair` BSDF uses (its local y, `sh_frame.t`) on a fiber along
    x hit from +z, for both curve setups."""
    import mitsuba as mi

    fiber = np.array([[[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]])
    log("\n## Mitsuba's fiber frame on a fiber along x, seen from +z\n")
    log("| curve | offset y | normal | BSDF's fiber axis (`sh_frame.t`) | angle to the fiber |")
    log("|---|---|---|---|---|")
    for kind, triple in [("linear", False), ("bspline", True)]:
        path = work / "geometry" / f"one-fiber.{kind}.txt"
        write_mitsuba_curves(path, fiber, 0.1, triple)
        scene = mi.load_dict({"type": "scene", "fiber": {"type": f"{kind}curve",
                                                         "filename": str(path)}})
        for y in [0.0, 0.05, -0.08]:
            si = scene.ray_intersect(mi.Ray3f(mi.Point3f(0.2, y, 3.0), mi.Vector3f(0, 0, -1)))
            n, axis = np.array(si.n), np.array(si.sh_frame.t)
            angle = np.degrees(np.arccos(min(1.0, abs(axis[0]))))
            log(f"| {kind}curve | {y} | {fmt_vec(n)} | {fmt_vec(axis)} | {angle:.0f}° |")


def envmap_check(log):
    """Where Mitsuba's `envmap`, turned by rotate_y(R + 180°), reads a map at the centre of
    each texel as tress maps it (`EnvironmentMap::direction_at`: u = 0.5 at −z turned by R,
    v = 0 at +y): a 1024 × 512 map whose red is its column and green its row, so Mitsuba's
    bilinear lookup returns the position it reads, in texels."""
    import mitsuba as mi

    w, h = 1024, 512
    img = np.zeros((h, w, 3), np.float32)
    img[..., 0] = np.arange(w)[None, :]
    img[..., 1] = np.arange(h)[:, None]
    img[..., 2] = 1.0
    cols = np.arange(8, w - 8, 7)  # away from the seam, where red wraps from 1023 to 0
    rows = np.arange(0, h, 5)
    i, j = [a.ravel() for a in np.meshgrid(cols, rows)]
    u, v = (i + 0.5) / w, (j + 0.5) / h
    log("\n## The Venice map's mapping: Mitsuba `envmap` at tress's texel centres\n")
    log(f"A {w} × {h} map whose red is the column and green the row; Mitsuba's lookup at the "
        f"direction of each of {len(i)} texel centres of tress's mapping (rotation R, Mitsuba "
        "`to_world` = rotate_y(R + 180°), no mirror). Mitsuba interpolates bilinearly between "
        "texels it places at u = (column + ½)/width like tress, but at v = row/(height − 1) "
        "(rows on the poles), against tress's (row + ½)/height: up to half a texel at the "
        "poles, none at the horizon.\n")
    log("| tress rotation R | column read − column (max abs) | row read − row: at the horizon "
        "| at the poles (max abs) |")
    log("|---|---|---|---|")
    for rot in [0.0, VENICE_ROTATION, 37.5]:
        em = mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(img),
                           "to_world": mi.ScalarTransform4f().rotate(axis=[0, 1, 0],
                                                                     angle=rot + 180.0)})
        elev = 0.5 * np.pi - v * np.pi
        phi = (u - 0.5) * 2 * np.pi - np.radians(rot)
        d = np.stack([np.cos(elev) * np.sin(phi), np.sin(elev), -np.cos(elev) * np.cos(phi)], 1)
        si = mi.SurfaceInteraction3f()
        got = []
        for k in range(len(d)):
            si.wi = mi.Vector3f(*(-d[k]))
            got.append(np.array(em.eval(si)))
        got = np.array(got)
        dcol = np.abs(got[:, 0] - i).max()
        drow = got[:, 1] - j
        horizon = np.abs(drow[np.abs(j - h / 2 + 0.5) < 3]).max()
        log(f"| {rot:g}° | {dcol:.3f} | {horizon:.3f} | {np.abs(drow).max():.3f} |")


def fmt_vec(v):
    return "(" + ", ".join(f"{x:+.2f}" for x in v) + ")"


def markdown(header, rows):
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(out)


def main():
    if len(sys.argv) > 1 and sys.argv[1] == "mitsuba-child":
        return mitsuba_render_main(sys.argv[2:])
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tress", type=Path, required=True, help="the tress binary")
    ap.add_argument("--work", type=Path, required=True, help="geometry, scenes, images")
    ap.add_argument("--data", type=Path, required=True, help="the shared data folder")
    ap.add_argument("--quick", action="store_true", help="a smoke run: small, few rounds")
    ap.add_argument("--rounds", type=int, help="alternating rounds (default 7; quick 2)")
    ap.add_argument("--ref-spp", type=int, help="spp of the references (default 256; quick 128)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--timing-only", action="store_true",
                    help="skip the converged-image table (its references stay cached)")
    ap.add_argument("--log", type=Path, help="also write the report here (markdown)")
    ap.add_argument("--light", choices=["sky", "venice", "both"], default="both",
                    help="white constant sky, the Venice map, or both in turn (default)")
    ap.add_argument("--overlaps", choices=["PassThrough", "Scatter"], default="PassThrough",
                    help="tress's convention in the time, noise and Embree tables (default "
                         "PassThrough: tress's default and Mitsuba's)")
    args = ap.parse_args()

    import mitsuba as mi

    mi.set_variant("scalar_rgb")  # the parent only reads images
    if mi.__version__ != MITSUBA_VERSION:
        sys.exit(f"Mitsuba {mi.__version__} found, {MITSUBA_VERSION} wanted")
    cfg = argparse.Namespace(
        res=48 if args.quick else 128, spp=16 if args.quick else 64,
        ref_spp=args.ref_spp or (128 if args.quick else 256),
        rounds=args.rounds or (2 if args.quick else 7), overlaps=args.overlaps)
    lights = [Light(name, args.data) for name in
              (["sky", "venice"] if args.light == "both" else [args.light])]
    args.work.mkdir(parents=True, exist_ok=True)
    lines = []

    def log(text=""):
        print(text, flush=True)
        lines.append(text)
        if args.log:  # kept up to date, so a long run's finished tables survive an interruption
            args.log.parent.mkdir(parents=True, exist_ok=True)
            args.log.write_text("\n".join(lines) + "\n")

    log(f"# tress against Mitsuba {MITSUBA_VERSION} (llvm_ad_rgb)\n")
    log(f"{cfg.res}², {cfg.spp} spp, {args.threads} threads, path tracing (64 scattering "
        f"events, roulette from {RR_DEPTH}), "
        f"{' and '.join(light.label for light in lights)}, Chiang σ_a = {SIGMA_A}, "
        f"β_m = β_n = {BETA_M}, α = {ALPHA_DEG}°, η = {ETA}; tress `overlaps: {cfg.overlaps}` "
        f"in the time tables; references {cfg.ref_spp} spp; "
        f"{cfg.rounds} alternating rounds{' (quick)' if args.quick else ''}.")
    start = time.perf_counter()
    scenes = build_scenes(args.work, args.data, args.quick)
    frame_check(args.work, log)
    if any(light.map for light in lights):
        envmap_check(log)
    r = Renderers(args, args.work)
    for light in lights:
        log(f"\n# Under the {light.label}")
        light_tables(r, scenes, light, cfg, args, log)
    log(f"\n(whole run {time.perf_counter() - start:.0f} s)")
    if args.log:
        print(f"wrote {args.log}")


def light_tables(r, scenes, light, cfg, args, log):
    """The three tables under one light."""
    if not args.timing_only:
        print(f"converged images, {light.label}:", flush=True)
        header, rows = image_table(r, scenes, light, cfg)
        log("\n## Converged images: mean over the hair against Mitsuba's frame-correct setup\n")
        log("Pixels the hair covers fully (tress's alpha); Mitsuba `bsplinecurve ×3` draws the "
            "same polylines as `linearcurve` with a correct fiber frame (README.md). tress "
            "with `overlaps: PassThrough` (its default, Mitsuba's convention) and `Scatter`.\n")
        log(markdown(header, rows))
    print(f"timing and noise, {light.label}:", flush=True)
    header, rows, equal_error = timing_table(r, scenes, light, cfg, log)
    log("\n## Time and noise at equal spp\n")
    log("Ratios are tress ÷ Mitsuba, each the median over the rounds of the ratio within a "
        "round; render-only time: tress's own render time, Mitsuba's `mi.render` and "
        "evaluation less any kernel compilation (the seconds shown are medians); relMSE is the "
        "mean over rounds against the renderer's own reference (corrected for the reference's "
        "noise); time to equal error = time ratio × relMSE ratio.\n")
    log(markdown(header, rows))
    print(f"Embree alone on tress's rays, {light.label}:", flush=True)
    header, rows = embree_bound_table(r, scenes, light, cfg, equal_error)
    log("\n## Embree alone on tress's rays\n")
    log("`tress bench --scene` on each tress scene above (same film and spp): the path "
        "tracer's rate over Embree alone tracing exactly its rays again (per CPU-second; each "
        "ray leaving a fiber started where it leaves that fiber, so Embree finds the hits the "
        "self-intersection rule keeps; in brackets, rays allowed to stop at their own fiber). "
        "The last column is the time to equal error a renderer whose only cost were Embree's "
        "would reach against Mitsuba `linearcurve`: below it, no shading speed-up helps.\n")
    log(markdown(header, rows))


if __name__ == "__main__":
    main()
