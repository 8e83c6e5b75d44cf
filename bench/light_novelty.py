#!/usr/bin/env python3
"""The novelty suite for light: does the soft cache keep its tolerance on lights outside the range
it was trained on?

Two scenes, each through the farm commands a user types (`pmsc export-frames`, `pmsc train`,
`pmsc replay`):
- cornell: the measured Cornell box's indirect light (`cornell:points=P,samples=S`), trained on the
  144 lights of the 12 x 12 grid under the ceiling;
- volume: light scattered in the demo's smoke (Debian's Wuson mesh made smoke by `pmsc demo volume
  --voxels V`), trained on the rig's lights around it (`volume:FILE.vdb`).
Replayed through each model: the lights between the training ones (cornell `scattered`, volume
`between`), the demos' light path (`path`), and 24 lights outside the trained range (`outside`:
lower in the box, beyond the grid, another colour; below the rig's elevations, colours outside its
range, nearer the medium). T is the demos' tolerance: 10% of the brightest training value.

Each model is `pmsc train --tolerance T` with one of the variants' options; the word POSITIONS in a
variant becomes `--positions FILE` (the points' positions, from `pmsc export-frames --positions`).
For each scene, variant and set the table gives the hits, the frames whose soft-cached error exceeds
T (hits, blends and local frames alike: what a user would get), the worst frame as a multiple of T,
and the share of points computed in full.

    /usr/bin/python3 bench/light_novelty.py --bin build/bin --work /tmp/light-novelty \\
        [--scenes cornell,volume] [--quick] [--variant '--sentinels 0'] [--no-variants]

The default variants are the defaults with and without positions, shared channels with and without
them, and `--energy 0.99999` with and without them. `--quick` uses 20,000 Cornell points at 64
samples and 12,000 voxels; the ctest `novelty.light` (label novelty) runs it with all six.

Needs numpy (the system python3). Exits 2 with one line on bad arguments or a failed command, 77
when Debian's assimp-testmodels (the smoke's mesh) is missing and CI is not set (a skip; under CI
it is exit 2), and 1 when any frame of any set comes back over T.
"""
import argparse
import json
import os
import sys

from suite_common import add_clean_argument, discard, fail, run, skip_or_fail, summarise

MESH = "/usr/share/assimp/models/OBJ/WusonOBJ.obj"
VARIANTS = ["POSITIONS", "", "--shared-channels POSITIONS", "--shared-channels", "--energy 0.99999 POSITIONS",
            "--energy 0.99999"]
SETS = {"cornell": ("training", ["scattered", "path", "outside"]),
        "volume": ("training", ["between", "path", "outside"])}






def scene_spec(args, scene, work):
    """The evaluator spec of a scene without its lights option, making the smoke's density first."""
    if scene == "cornell":
        points, samples = (20000, 64) if args.quick else (40000, 160)
        return "cornell:points=%d,samples=%d," % (points, samples)
    density = os.path.join(work, "smoke", "density.vdb")
    if not os.path.exists(density):
        voxels = 12000 if args.quick else 60000
        run([os.path.join(args.bin, "pmsc"), "demo", "volume", "--quick", "--quiet", "--no-vdb-render", "--out",
             os.path.dirname(density), "--voxels", str(voxels)])
    return "volume:" + density + ":"


def export_sets(args, scene, work):
    """The scene's frames (float32) and positions, made once per work folder."""
    spec = scene_spec(args, scene, work)
    training, others = SETS[scene]
    paths = {}
    for lights in [training] + others:
        paths[lights] = os.path.join(work, lights + ".npy")
        if os.path.exists(paths[lights]):
            continue
        cmd = [os.path.join(args.bin, "pmsc"), "export-frames", spec + "lights=" + lights, "--out", paths[lights],
               "--dtype", "float32", "--quiet"]
        if lights == training:
            cmd += ["--positions", os.path.join(work, "positions.npy")]
        run(cmd)
    return paths




def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--bin", default="build/bin", help="folder of pmsc")
    p.add_argument("--work", required=True, help="folder for frames, models and reports (reused)")
    p.add_argument("--scenes", default="cornell,volume", help="scenes to run, of cornell,volume")
    p.add_argument("--quick", action="store_true", help="small scenes (the ctest)")
    p.add_argument("--variant", action="append", default=None,
                   help="pmsc train options of a model (repeatable; POSITIONS: --positions FILE); "
                        "default: " + "; ".join(v or "(defaults)" for v in VARIANTS))
    p.add_argument("--no-variants", action="store_true", help="the defaults with positions alone")
    add_clean_argument(p)
    args = p.parse_args()
    try:
        import numpy as np
    except ImportError:
        fail("needs numpy (run it with the system python3)")
    scenes = [s for s in args.scenes.split(",") if s]
    for s in scenes:
        if s not in SETS:
            fail("no scene '%s' (scenes: cornell,volume)" % s)
    if "volume" in scenes and not os.path.exists(MESH):
        skip_or_fail("no " + MESH + " (apt-get install assimp-testmodels)")
    variants = ["POSITIONS"] if args.no_variants else (args.variant if args.variant is not None else VARIANTS)
    print("| scene | pmsc train options | M | sentinels | " +
          " | ".join("%s: hits, over T (hits), worst, points computed" % s for s in ["between", "path", "outside"]) +
          " |")
    print("|---|---|---|---|---|---|---|")
    any_over = False
    for scene in scenes:
        work = os.path.join(args.work, scene + ("-quick" if args.quick else ""))
        os.makedirs(work, exist_ok=True)
        paths = export_sets(args, scene, work)
        training, others = SETS[scene]
        q = np.load(paths[training]).astype(np.float64)
        tolerance = 0.1 * float(np.sqrt((q ** 2).sum(-1)).max())
        del q
        positions = os.path.join(work, "positions.npy")
        for v, variant in enumerate(variants):
            model = os.path.join(work, "m%d.pmsc" % v)
            options = []
            for word in variant.split():
                options += ["--positions", positions] if word == "POSITIONS" else [word]
            train = run([os.path.join(args.bin, "pmsc"), "train", "--frames", paths[training], "--out", model,
                         "--tolerance", "%.6g" % tolerance, "--quiet"] + options)
            basis = train.split("M = ")[1].split(",")[0] if "M = " in train else "?"
            info = json.loads(run([os.path.join(args.bin, "pmsc"), "inspect", model, "--json"]))
            sentinels = info.get("sentinels", {})
            promised = float(info["tolerance"])  # T as the model keeps it (the command line's digits)
            cells = []
            for lights in others:
                report = model + "." + lights + ".json"
                run([os.path.join(args.bin, "pmsc"), "replay", "--model", model, "--frames", paths[lights],
                     "--report", report, "--quiet"])
                r = summarise(report, promised)
                any_over = any_over or r["over"] > 0
                cells.append("%d of %d, %d (%d), %.3f T, %.1f%%" % (r["hits"], r["frames"], r["over"], r["over_hits"],
                                                                   r["worst"], 100 * r["evaluated"]))
            print("| %s | %s | %s | %s | %s |" % (
                scene, variant.replace("POSITIONS", "--positions") or "(defaults)", basis,
                "%d (%s)" % (sentinels["count"], sentinels["positions"]) if sentinels else "none",
                " | ".join(cells)), flush=True)
            discard(args, [model])
        discard(args, list(paths.values()) + [positions])
    return 1 if any_over else 0


if __name__ == "__main__":
    sys.exit(main())
