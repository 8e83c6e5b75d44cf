#!/usr/bin/env python3
"""Each way pmsc's Blender child fails gives one line naming what went wrong, exit code 3 from
`pmsc export-frames`, and no output file (and the values it must give: controls, seeds, passes); animate_light.py's, show_values.py's and
bvh_character.py's bad requests exit 2 with one line and write nothing (docs/blender.md, "Failures").

Exit codes: 0 every case as expected, 1 a case was not, 77 no Blender and CI not set (a skip; under
CI it is a failure, exit 2).
"""
import argparse
import os
import shutil
import socket
import struct
import subprocess
import sys


def ask(command, requests):
    """Starts the exec child `command` (docs/exec-protocol.md) and returns its answers, as float64
    arrays, to `requests`: (frame, point indices) pairs, None indices asking for every point."""
    import numpy as np
    hello, request, response = struct.Struct("<8sIIQQ"), struct.Struct("<IIqQQ"), struct.Struct("<IIQ")
    ours, its = socket.socketpair()
    child = subprocess.Popen(command, shell=True, stdin=its, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    its.close()

    def read(size):
        data = bytearray()
        while len(data) < size:
            chunk = ours.recv(size - len(data))
            if not chunk:
                raise EOFError("the child closed its socket: " + child.stderr.read().decode()[-300:])
            data += chunk
        return bytes(data)

    _, _, channels, count, _ = hello.unpack(read(hello.size))
    answers = []
    for frame, ids in requests:
        if ids is None:
            ours.sendall(request.pack(2, 0, frame, count, 0))
        else:
            ours.sendall(request.pack(1, 0, frame, len(ids), 0) + np.asarray(ids, dtype="<u8").tobytes())
        status, _, length = response.unpack(read(response.size))
        data = read(length * (8 if status == 0 else 1))
        if status != 0:
            raise RuntimeError(data.decode())
        answers.append(np.frombuffer(data, "<f8").reshape(-1, channels))
    ours.close()
    child.wait()
    return answers


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--bin", required=True)
    p.add_argument("--share", required=True)
    p.add_argument("--work", required=True)
    args = p.parse_args()
    if shutil.which("blender") is None:
        if os.environ.get("CI", "") in ("", "false", "0"):
            print("blender_failures: no blender on PATH: skipped", file=sys.stderr)
            return 77
        print("blender_failures: no blender on PATH (apt-get install blender)", file=sys.stderr)
        return 2
    os.makedirs(args.work, exist_ok=True)
    w = lambda name: os.path.join(args.work, name)
    launcher = os.path.join(args.share, "pmsc-blender")
    pmsc = os.path.join(args.bin, "pmsc")
    built = subprocess.run(["blender", "-b", "--factory-startup", "--python-exit-code", "2", "--python",
                            os.path.join(args.share, "cornell_box.py"), "--", "--out", w("box.blend"), "--grid", "2",
                            "--path", "1"], capture_output=True, text=True)
    sampled = subprocess.run([launcher, w("box.blend"), "sample", "--out", w("points.npy"), "--count", "50"],
                             capture_output=True, text=True)
    if built.returncode != 0 or sampled.returncode != 0:
        print("blender_failures: could not build the scene: " + (built.stderr + sampled.stderr)[-400:], file=sys.stderr)
        return 1
    with open(w("bad.npy"), "wb") as f:
        f.write(b"not a numpy file")
    with open(w("bad.vdb"), "wb") as f:
        f.write(b"not an OpenVDB file")
    # Controls by data path: the light's power and place, a row per frame (5 x 4).
    import numpy as np
    np.savez(w("controls.npz"), a=np.ones(5))
    np.save(w("samples.npy"), np.full(5, 4.0))  # an int property set from floats
    np.save(w("controls.npy"), np.array([[100.0, 2, 2, 4], [200, 2, 2, 4], [100, 2, 2, 4], [400, 2, 2, 4], [50, 2, 2, 4]]))
    with open(w("crash.py"), "w") as f:  # a Blender that dies in the middle of a frame
        f.write("import os, signal\nos.kill(os.getpid(), signal.SIGSEGV)\n")
    serve = lambda blend, *rest: "exec:%s %s serve --points %s --frames 1-5 --samples 4 %s" % (
        launcher, blend, w("points.npy"), " ".join(rest))
    cases = [
        ("no .blend", serve(w("missing.blend")), "cannot read"),
        ("not a .blend", serve(w("points.npy")), "is not a .blend file"),
        ("bad points", "exec:%s %s serve --points %s --frames 1-5" % (launcher, w("box.blend"), w("bad.npy")), "bad.npy"),
        ("bad frames", "exec:%s %s serve --points %s --frames 5-1" % (launcher, w("box.blend"), w("points.npy")),
         "LAST is before FIRST"),
        ("bad light", serve(w("box.blend"), "--light sun"), "'sun' is not direct or indirect"),
        ("no light", serve(w("box.blend"), "--set 'objects[\"Nope\"].data.energy' --controls " + w("controls.npy")),
         "bpy.data.objects has no 'Nope'"),
        ("no property", serve(w("box.blend"), "--set 'objects[\"Light\"].data.nope' --controls " + w("controls.npy")),
         "'Light' has no property 'data.nope'"),
        ("bad controls", serve(w("box.blend"), "--set 'objects[\"Light\"].data.energy' --controls " + w("controls.npy")),
         "expected 5 x 1 finite values"),
        ("npz controls", serve(w("box.blend"), "--set 'objects[\"Light\"].data.energy' --controls " + w("controls.npz")),
         "expected one array of numbers"),
        ("no blender", serve(w("box.blend")), "no 'no-such-blender' on PATH"),
        ("crash", "exec:blender -b %s --python %s 1>&2" % (w("box.blend"), w("crash.py")), "signal"),
        # pose: the evaluated vertices of a mesh posed by its rig
        ("no object", "exec:%s %s pose --object Nope --frames 1-5" % (launcher, w("box.blend")),
         "the scene has no mesh object named 'Nope'"),
        ("no action", "exec:%s %s pose --object floor --action walk --frames 1-5" % (launcher, w("box.blend")),
         "the .blend has no action named 'walk'"),
        ("no rig", "exec:%s %s pose --object floor --frames 1-5" % (launcher, w("box.blend")),
         "'floor' has no Armature modifier whose root bone --space root could follow"),
    ]
    bad = 0
    for name, spec, expected in cases:
        env = dict(os.environ)
        if name == "no blender":
            env["PMSC_BLENDER"] = "no-such-blender"
        out = w("out.npy")
        if os.path.exists(out):
            os.remove(out)
        done = subprocess.run([pmsc, "export-frames", spec, "--out", out, "--quiet"], capture_output=True, text=True,
                              env=env)
        lines = [l for l in done.stderr.splitlines() if l.strip()]
        ok = done.returncode == 3 and len(lines) == 1 and expected in lines[0] and not os.path.exists(out)
        print("%-12s exit %d: %s" % (name, done.returncode, lines[-1] if lines else "(nothing)"))
        if not ok:
            print("blender_failures: %s: expected exit 3, one line containing '%s', no %s" % (name, expected, out),
                  file=sys.stderr)
            bad += 1
    # The light a point receives is linear in the light's power: frames whose --set power doubles,
    # at the same place (the same samples), give twice the values.
    out = w("controls-out.npy")
    done = subprocess.run([pmsc, "export-frames", serve(w("box.blend"), "--set 'objects[\"Light\"].data.energy' "
                           "--set 'objects[\"Light\"].location' --controls " + w("controls.npy")),
                           "--out", out, "--quiet"], capture_output=True, text=True)
    if done.returncode != 0:
        print("blender_failures: controls: " + done.stderr[-300:], file=sys.stderr)
        bad += 1
    else:
        e = np.load(out)
        done = subprocess.run([pmsc, "export-frames", serve(w("box.blend"), "--set 'scenes[Scene].cycles.samples' "
                               "--controls " + w("samples.npy")), "--out", w("samples-out.npy"), "--frames", "0",
                               "--quiet"], capture_output=True, text=True)
        if done.returncode != 0:
            print("blender_failures: an int property from a float table: " + done.stderr[-300:], file=sys.stderr)
            bad += 1
        ratios = [float(np.abs(e[i] - k * e[0]).max() / e[0].max()) for i, k in ((1, 2), (2, 1), (3, 4))]
        print("controls     frames at power 200, 100, 400 against 100: largest relative differences %s" % ratios)
        if max(ratios) > 1e-5:
            print("blender_failures: controls: the values do not follow the --set power", file=sys.stderr)
            bad += 1
    # A point's value does not depend on the other points of its call (its samples are seeded by
    # the point): every point, then three subsets in other orders, give the same bits.
    try:
        full, some, reversed_, one = ask(serve(w("box.blend"))[len("exec:"):], [(2, None), (2, [3, 17, 40, 41]),
                                                                 (2, [41, 40, 17, 3]), (2, [17])])
        differs = max(float(np.abs(full[[3, 17, 40, 41]] - some).max()),
                      float(np.abs(full[[41, 40, 17, 3]] - reversed_).max()), float(np.abs(full[[17]] - one).max()))
        print("seeds        a point alone, with others, in another order against every point: largest difference %g"
              % differs)
        if differs != 0 or not full.any():
            print("blender_failures: seeds: a point's value depends on the other points of its call", file=sys.stderr)
            bad += 1
    except (EOFError, RuntimeError) as error:
        print("blender_failures: seeds: %s" % error, file=sys.stderr)
        bad += 1
    # The passes: the indirect light alone is light (not zeros), and direct + indirect is both passes'
    # bake at the same seed.
    try:
        passes = {}
        for light in ("direct", "indirect", "direct,indirect"):
            passes[light] = ask(serve(w("box.blend"), "--light", light)[len("exec:"):], [(2, None)])[0]
        direct, indirect, both = passes["direct"], passes["indirect"], passes["direct,indirect"]
        apart = float(np.abs(direct + indirect - both).max() / both.max())
        print("passes       indirect mean %.4g (both %.4g); direct + indirect against both: largest relative "
              "difference %g" % (indirect.mean(), both.mean(), apart))
        if not indirect.mean() > 0.05 * both.mean() or indirect.min() < 0 or apart > 1e-6:
            print("blender_failures: passes: --light indirect is not both passes less the direct one", file=sys.stderr)
            bad += 1
    except (EOFError, RuntimeError) as error:
        print("blender_failures: passes: %s" % error, file=sys.stderr)
        bad += 1
    # animate_light.py (a light keyed on a .blend): bad requests end Blender with exit 2, one line
    # on stderr, and no .blend written.
    animate = lambda *rest: ["blender", "-b", w("box.blend"), "--python-exit-code", "2", "--python",
                             os.path.join(args.share, "animate_light.py"), "--", "--out", w("lit.blend")] + list(rest)
    # show_values.py (values or the scene lit by them, rendered): the same.
    show = lambda *rest: ["blender", "-b", w("box.blend"), "--python-exit-code", "2", "--python",
                          os.path.join(args.share, "show_values.py"), "--", "--points", w("points.npy"), "--full",
                          w("points.npy"), "--pmsc", w("points.npy"), "--out", w("lit.blend")] + list(rest)
    for name, cmd, expected in [
        ("no such light", animate("--light", "Nope"), "the scene has no light named 'Nope'"),
        ("bad lattice", animate("--grid", "1"), "--grid must be at least 2"),
        ("bad subdivide", show("--surfaces", "--subdivide", "9"), "--subdivide must be 0 to 6"),
        ("bad values", show("--surfaces"), "values of shape"),
        ("bad cache", show("--full", w("bad.vdb")), "not a pmsc light cache"),
        # bvh_character.py (a character from motion capture): a take that is not a BVH file
        ("bad take", ["blender", "-b", "--factory-startup", "--python-exit-code", "2", "--python",
                      os.path.join(args.share, "bvh_character.py"), "--", "--bvh", w("bad.npy"),
                      "--out", w("lit.blend")], "not a BVH file"),
    ]:
        done = subprocess.run(cmd, capture_output=True, text=True)
        lines = [l for l in done.stderr.splitlines() if l.strip()]
        ok = done.returncode == 2 and len(lines) == 1 and expected in lines[0] and not os.path.exists(w("lit.blend"))
        print("%-12s exit %d: %s" % (name, done.returncode, lines[-1] if lines else "(nothing)"))
        if not ok:
            print("blender_failures: %s: expected exit 2, one line containing '%s', no lit.blend; got %s"
                  % (name, expected, done.stderr[-300:]), file=sys.stderr)
            bad += 1
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
