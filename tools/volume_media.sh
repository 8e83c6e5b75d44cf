#!/bin/sh
# The three media of docs/volume.md ("Other media"), which the volume cache's defaults were not
# chosen on, made from Debian's assimp-testmodels (apt-get install assimp-testmodels
# libopenvdb-tools). The .vdb files are a few MB each, so they are made, not stored.
#
# Usage: tools/volume_media.sh OUTDIR [PMSC]      (PMSC: the pmsc binary, default build/bin/pmsc)
# Then, for each: build/bin/pmsc demo volume --out OUT --density OUTDIR/NAME.vdb
set -eu
if [ $# -lt 1 ]; then
    echo "usage: $0 OUTDIR [PMSC]" >&2
    exit 2
fi
out=$1
pmsc=${2:-build/bin/pmsc}
models=/usr/share/assimp/models
mkdir -p "$out"

# 1. Uniform density from another mesh, the grid named by vdb_tool (ls2fog_mesh2ls_Spider_binary):
#    the spider, 145,883 active voxels of density 1 (ramping to 0 over the 3 voxels under the
#    surface), 155 x 199 x 82 voxels.
vdb_tool -read "$models/STL/Spider_binary.stl" -mesh2ls voxel=0.04 -ls2fog -write "$out/spider.vdb"

# 2. Thin and wispy: the rock 'fels' as smoke of density 0.3 x fog x n^4 (n: the demo's fractal
#    noise in [0, 1], no floor), so the density peaks in sparse lumps and is near zero between
#    them. pmsc's own mesh-to-smoke writes it (the --quick run is only there to write the grid).
"$pmsc" demo volume --quick --quiet --no-vdb-render --out "$out/wispy-quick" \
    --mesh "$models/3DS/fels.3ds" --voxels 155000 --fog-density 0.3 --fog-floor 0 --fog-exponent 4
mv "$out/wispy-quick/density.vdb" "$out/wispy.vdb"
rm -rf "$out/wispy-quick"

# 3. Dense: a uniform dodecahedron (OpenVDB's platonic solid), 145,859 active voxels of density 1;
#    with the default extinction (16 / longest side per unit density) the optical depth through
#    its middle is 13 to 16.
vdb_tool -platonic faces=12 scale=2 voxel=0.053 -ls2fog -write "$out/dodecahedron.vdb"

for f in spider wispy dodecahedron; do vdb_print "$out/$f.vdb"; done
