#include "viewer/RelightScene.h"

#include "pmsc/Errors.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>

namespace pmsc::viewer {

std::unique_ptr<RelightScene> makeVolumeScene(const std::string& args);   // VolumeRelight.cpp
std::unique_ptr<RelightScene> makeCornellScene(const std::string& args);  // CornellRelight.cpp

namespace {

std::string number(double v) {
    std::ostringstream s;
    s << v;
    return s.str();
}

/// "unknown control 'hue' (the volume scene has azimuth, elevation, kelvin)".
InputError unknownControl(const std::string& name, const std::string& kind,
                          const std::vector<Control>& list) {
    std::string names;
    for (const Control& k : list) {
        if (!names.empty()) names += ", ";
        names += k.name;
    }
    return InputError("unknown control '" + name + "' (the " + kind + " scene has " + names + ")");
}

}  // namespace

Controls RelightScene::defaults() const {
    Controls c;
    for (const Control& k : controls()) c[k.name] = k.value;
    return c;
}

Controls RelightScene::resolve(const Controls& given) const {
    Controls c = defaults();
    for (const auto& entry : given) {
        const std::string& name = entry.first;
        const double value = entry.second;
        const auto& list = controls();
        const auto it =
            std::find_if(list.begin(), list.end(), [&](const Control& k) { return k.name == name; });
        if (it == list.end()) throw unknownControl(name, kind(), list);
        if (!std::isfinite(value) || value < it->min || value > it->max) {
            throw InputError("control '" + name + "' = " + number(value) + " is outside [" + number(it->min) +
                             ", " + number(it->max) + "] " + it->unit);
        }
        c[name] = value;
    }
    return c;
}

std::unique_ptr<RelightScene> makeRelightScene(const std::string& spec) {
    const auto colon = spec.find(':');
    const std::string kind = spec.substr(0, colon);
    const std::string args = colon == std::string::npos ? "" : spec.substr(colon + 1);
    if (kind == "volume") return makeVolumeScene(args);
    if (kind == "cornell") return makeCornellScene(args);
    throw InputError("scene '" + spec + "' is neither volume:FILE.vdb[:OPTIONS] nor cornell[:OPTIONS]");
}

DenseLayout DenseLayout::of(const std::vector<std::array<double, 3>>& positions, double voxel) {
    if (!(voxel > 0)) throw InputError("dense layout: voxel size must be positive");
    DenseLayout d;
    d.voxel = voxel;
    if (positions.empty()) return d;
    double lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
        lo[a] = std::numeric_limits<double>::infinity();
        hi[a] = -lo[a];
    }
    for (const auto& p : positions) {
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::min(lo[a], p[size_t(a)]);
            hi[a] = std::max(hi[a], p[size_t(a)]);
        }
    }
    for (int a = 0; a < 3; ++a) {
        d.origin[a] = lo[a];
        d.dims[a] = std::llround((hi[a] - lo[a]) / voxel) + 1;
    }
    if (double(d.dims[0]) * double(d.dims[1]) * double(d.dims[2]) >
        double(std::numeric_limits<std::uint32_t>::max()))
        throw InputError("dense layout: the points' box has more than 2^32 voxels");
    d.index.reserve(positions.size());
    for (const auto& p : positions) {
        std::int64_t ijk[3];
        for (int a = 0; a < 3; ++a) {
            ijk[a] = std::clamp<std::int64_t>(std::llround((p[size_t(a)] - lo[a]) / voxel), 0, d.dims[a] - 1);
        }
        d.index.push_back(std::uint32_t(ijk[0] + d.dims[0] * (ijk[1] + d.dims[1] * ijk[2])));
    }
    return d;
}

nlohmann::json DenseLayout::toJson() const {
    return {{"dims", {dims[0], dims[1], dims[2]}},
            {"origin", {origin[0], origin[1], origin[2]}},
            {"voxel", voxel}};
}

}  // namespace pmsc::viewer
