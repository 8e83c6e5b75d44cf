// libFuzzer target: the OBJ reader (pmsc/ObjIO), which reads the ICT face's meshes and, on every
// resumed `pmsc run --format obj`, the frames a farm left behind (any bytes: a node may have died
// mid-write). The contract: readObj() returns a mesh whose polygons index its vertices, or throws
// pmsc::InputError; what it returns, formatObj() writes and readObj() reads back bit for bit.
#include "FuzzInput.h"

#include "pmsc/Errors.h"
#include "pmsc/ObjIO.h"

#include <cstdlib>
#include <cstring>

using namespace pmsc;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const fuzz::MemoryFile file(data, size);
    ObjMesh mesh;
    Index lines = 0;
    try {
        (void)readObj(file.path(), ObjContent::Positions, &lines);
        mesh = readObj(file.path(), ObjContent::PositionsAndPolygons);
    } catch (const InputError&) {
        return 0;
    }
    if (mesh.positions.size() % 3 != 0 || mesh.polygonCount() != lines) std::abort();
    for (std::int32_t v : mesh.polygonVertices)
        if (v < 0 || v >= mesh.vertexCount()) std::abort();
    const std::string text = formatObj(mesh, mesh.positions, "again");
    const fuzz::MemoryFile again(reinterpret_cast<const std::uint8_t*>(text.data()), text.size());
    const ObjMesh back = readObj(again.path(), ObjContent::PositionsAndPolygons);
    if (back.positions.size() != mesh.positions.size() ||
        (!mesh.positions.empty() &&  // bit for bit (-0 stays -0); an empty vector's data() is null
         std::memcmp(back.positions.data(), mesh.positions.data(), mesh.positions.size() * sizeof(double)) !=
             0) ||
        back.polygonStart != mesh.polygonStart || back.polygonVertices != mesh.polygonVertices)
        std::abort();
    return 0;
}
