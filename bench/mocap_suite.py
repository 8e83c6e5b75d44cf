#!/usr/bin/env python3
"""Motion capture through pmsc: real takes replayed through models trained on a range of motion.

Debian's assimp-testmodels has CMU takes 01_01 and 01_03 (subject 1) and Boxing_Toes (another
skeleton). Each skeleton is dressed in skinned tubes (`skin:CLIP.bvh:body=tubes:space=root`) and
trained on a range of motion a rigger would record (tools/bvh_range_of_motion.py), never on the takes:
- wide: every rotation channel swept to +-75 degrees, then 300 poses within +-45 (the calibration
  table of docs/results/calibration.md, at T = 3% and 2.5% of the body's diagonal);
- narrow: swept to +-25, then 300 poses within +-15, which the takes leave (the novelty rows, T = 3%).

For each model (pmsc train's defaults, and each --variant) and take the table gives the hits, the
frames whose soft-cached error exceeds T (hits, blends and local frames alike), the worst frame as a
multiple of T and the share of points computed in full.

    /usr/bin/python3 bench/mocap_suite.py --bin build/bin --work /tmp/mocap \\
        [--bvh /usr/share/assimp/models/BVH] [--variant '--energy 0.99999'] [--no-variants]

Exits 2 with one line on bad arguments or a failed command, 77 when the BVH folder is missing and CI
is not set (a skip; under CI it is exit 2), and 1 when any frame comes back over T.
"""
import argparse
import os
import sys

from suite_common import add_clean_argument, add_variant_arguments, discard, fail, models_of, require_folder, run, summarise

HERE = os.path.dirname(os.path.abspath(__file__))
ROM = os.path.join(HERE, "..", "tools", "bvh_range_of_motion.py")

# (skeleton's take, the body's bounding-box diagonal, the takes replayed): the diagonals are the
# tube bodies' (docs/results/calibration.md), T is a share of them.
SKELETONS = {
    "cmu": ("01_01", 29.0, ["01_01", "01_03"]),
    "box": ("Boxing_Toes", 187.0, ["Boxing_Toes"]),
}
# (range of motion, its tools/bvh_range_of_motion.py options, T in % of the diagonal)
RANGES = [
    ("wide", [], (3.0, 2.5)),
    ("narrow", ["--sweep", "25", "--mix", "15"], (3.0,)),
]


def frames(args, clip, out):
    if not os.path.exists(out):
        run([os.path.join(args.bin, "pmsc"), "export-frames",
             "skin:%s:fps=30:body=tubes:space=root" % clip, "--out", out, "--quiet"])
    return out


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--bin", default="build/bin", help="folder of pmsc")
    p.add_argument("--work", required=True, help="folder for frames, models and reports (reused)")
    p.add_argument("--bvh", default="/usr/share/assimp/models/BVH", help="assimp-testmodels' BVH folder")
    add_variant_arguments(p)
    add_clean_argument(p)
    args = p.parse_args()
    require_folder(args.bvh)
    os.makedirs(args.work, exist_ok=True)
    variants = models_of(args)
    print("| training | take | T | pmsc train options | M | hits | over T (hits / local) | worst | points computed |")
    print("|---|---|---|---|---|---|---|---|---|")
    any_over = False
    for rom_name, rom_options, shares in RANGES:
        for skeleton, (source, diagonal, takes) in SKELETONS.items():
            rom = os.path.join(args.work, "%s-%s.bvh" % (skeleton, rom_name))
            if not os.path.exists(rom):
                run([sys.executable, ROM, os.path.join(args.bvh, source + ".bvh"), rom] + rom_options)
            train_frames = frames(args, rom, rom[:-4] + ".npy")
            for share in shares:
                tolerance = share / 100 * diagonal
                for v, variant in enumerate(variants):
                    model = os.path.join(args.work, "%s-%s-%g-%d.pmsc" % (skeleton, rom_name, share, v))
                    out = run([os.path.join(args.bin, "pmsc"), "train", "--frames", train_frames, "--out",
                               model, "--tolerance", "%.6g" % tolerance] + variant.split())
                    basis = out.split("M = ")[1].split(",")[0] if "M = " in out else "?"
                    for take in takes:
                        take_frames = frames(args, os.path.join(args.bvh, take + ".bvh"),
                                             os.path.join(args.work, take + ".npy"))
                        report = "%s.%s.json" % (model, take)
                        run([os.path.join(args.bin, "pmsc"), "replay", "--model", model, "--frames",
                             take_frames, "--report", report, "--quiet"])
                        s = summarise(report, tolerance)
                        any_over = any_over or s["over"] > 0
                        print("| %s %s | %s | %g%% | %s | %s | %d of %d | %d (%d / %d) | %.3f T | %.1f%% |"
                              % (skeleton, rom_name, take, share, variant or "(defaults)", basis, s["hits"],
                                 s["frames"], s["over"], s["over_hits"], s["over_local"], s["worst"],
                                 100 * s["evaluated"]), flush=True)
                    discard(args, [model])
            discard(args, [train_frames])
    discard(args, [os.path.join(args.work, take + ".npy") for _, _, takes in SKELETONS.values() for take in takes])
    return 1 if any_over else 0


if __name__ == "__main__":
    sys.exit(main())
