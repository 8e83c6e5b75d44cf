#include "examples/synthetic/IctFrames.h"

#include "evaluators/synthetic/SmoothNoise.h"
#include "pmsc/Errors.h"
#include "pmsc/ObjIO.h"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <sstream>

namespace pmsc::synthetic {

namespace {

/// The "v x y z" lines of an OBJ file, as 3N doubles (the project's one OBJ reader).
std::vector<double> readObjVertices(const std::string& path) {
    std::vector<double> v = readObj(path, ObjContent::Positions).positions;
    if (v.empty()) throw InputError(path + ": no vertices");
    return v;
}

}  // namespace

IctRig loadIctRig(const std::string& folder) {
    namespace fs = std::filesystem;
    if (!fs::is_directory(folder))
        throw InputError(folder + ": not a folder (expected the ICT FaceKit meshes)");
    const std::string neutralPath = (fs::path(folder) / "generic_neutral_mesh.obj").string();
    if (!fs::exists(neutralPath))
        throw InputError(neutralPath + ": no such file (is this the ICT FaceKit folder?)");
    IctRig rig;
    const std::vector<double> neutral = readObjVertices(neutralPath);
    rig.points = static_cast<Index>(neutral.size() / 3);
    rig.neutral = Eigen::Map<const Eigen::VectorXd>(neutral.data(), static_cast<Index>(neutral.size()));

    std::vector<std::string> files;
    for (const auto& e : fs::directory_iterator(folder))
        if (e.path().extension() == ".obj" && e.path().filename() != "generic_neutral_mesh.obj")
            files.push_back(e.path().string());
    std::sort(files.begin(), files.end());
    std::vector<double> jawOpen;
    for (const auto& file : files) {
        const std::vector<double> v = readObjVertices(file);
        if (v.size() != neutral.size())
            throw InputError(file + ": " + std::to_string(v.size() / 3) + " vertices, the neutral mesh has " +
                             std::to_string(rig.points));
        const std::string name = fs::path(file).stem().string();
        if (name == "jawOpen") {
            jawOpen = v;
            continue;
        }
        IctRig::Shape shape;
        shape.name = name;
        for (Index p = 0; p < rig.points; ++p) {
            const Eigen::Vector3d d(v[3 * p] - neutral[3 * p], v[3 * p + 1] - neutral[3 * p + 1],
                                    v[3 * p + 2] - neutral[3 * p + 2]);
            if (d.squaredNorm() > 1e-18) {
                shape.vertices.push_back(p);
                shape.deltas.push_back(d);
            }
        }
        rig.shapes.push_back(std::move(shape));
    }
    if (jawOpen.empty()) throw InputError(folder + ": no jawOpen.obj (needed for the jaw hinge)");

    // Fit the hinge over the vertices that move most (the rigid part of the jaw): a rotation
    // about the x axis through c maps (y, z) to R (y, z) + (I - R) c, which is linear in
    // (cos, sin, t_y, t_z) with t = (I - R) c: y' = cos y - sin z + t_y, z' = sin y + cos z + t_z.
    // Exact for a rigid rotation, unlike a tangent (small-angle) fit.
    std::vector<double> moved(static_cast<std::size_t>(rig.points));
    double most = 0;
    for (Index p = 0; p < rig.points; ++p) {
        const Eigen::Vector3d d(jawOpen[3 * p] - neutral[3 * p], jawOpen[3 * p + 1] - neutral[3 * p + 1],
                                jawOpen[3 * p + 2] - neutral[3 * p + 2]);
        moved[static_cast<std::size_t>(p)] = d.norm();
        most = std::max(most, d.norm());
    }
    if (!(most > 0)) throw InputError(folder + "/jawOpen.obj: the jaw does not move");
    std::vector<Index> fit;
    for (Index p = 0; p < rig.points; ++p)
        if (moved[static_cast<std::size_t>(p)] >= 0.5 * most) fit.push_back(p);
    Eigen::MatrixXd a(2 * static_cast<Index>(fit.size()), 4);
    Eigen::VectorXd b(a.rows());
    for (std::size_t i = 0; i < fit.size(); ++i) {
        const Index p = fit[i];
        const Index r = 2 * static_cast<Index>(i);
        const double y = neutral[3 * p + 1], z = neutral[3 * p + 2];
        a.row(r) << y, -z, 1, 0;
        b[r] = jawOpen[3 * p + 1];
        a.row(r + 1) << z, y, 0, 1;
        b[r + 1] = jawOpen[3 * p + 2];
    }
    const Eigen::Vector4d u = a.colPivHouseholderQr().solve(b);
    rig.jawAngle = std::atan2(u[1], u[0]);
    Eigen::Matrix2d rotation;
    rotation << std::cos(rig.jawAngle), -std::sin(rig.jawAngle), std::sin(rig.jawAngle),
        std::cos(rig.jawAngle);
    if (std::abs(rig.jawAngle) < 1e-9) throw InputError(folder + "/jawOpen.obj: the jaw does not rotate");
    rig.jawPivotYZ = (Eigen::Matrix2d::Identity() - rotation).inverse() * Eigen::Vector2d(u[2], u[3]);
    // A vertex's weight: the fraction of the full rotation's chord it travels.
    const double chordPerLever = 2 * std::abs(std::sin(0.5 * rig.jawAngle));
    for (Index p = 0; p < rig.points; ++p) {
        const double lever =
            std::hypot(neutral[3 * p + 1] - rig.jawPivotYZ[0], neutral[3 * p + 2] - rig.jawPivotYZ[1]);
        const double chord = chordPerLever * lever;
        if (moved[static_cast<std::size_t>(p)] < 1e-9 || chord < 1e-9) continue;
        rig.jawVertices.push_back(p);
        rig.jawWeights.push_back(std::min(1.0, moved[static_cast<std::size_t>(p)] / chord));
    }

    Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
    for (Index p = 0; p < rig.points; ++p) {
        const Eigen::Vector3d x = rig.neutral.segment<3>(3 * p);
        lo = lo.cwiseMin(x);
        hi = hi.cwiseMax(x);
    }
    rig.bboxDiagonal = (hi - lo).norm();
    return rig;
}

FrameSet poseIctFrames(const IctRig& rig, Index frames, unsigned seed,
                       const std::vector<std::string>& without,
                       const std::vector<std::pair<std::string, double>>& hold) {
    const auto shapeNamed = [&](const std::string& name) {
        const auto it = std::find_if(rig.shapes.begin(), rig.shapes.end(),
                                     [&](const IctRig::Shape& s) { return s.name == name; });
        if (it == rig.shapes.end())
            throw InputError("no blendshape '" + name +
                             "' in the rig (jawOpen is the hinge, not a blendshape)");
        return static_cast<std::size_t>(it - rig.shapes.begin());
    };
    // held[s]: shape s does not follow its curve; fixed[s] is its weight in every frame.
    std::vector<char> held(rig.shapes.size(), 0);
    std::vector<double> fixed(rig.shapes.size(), 0.0);
    for (const auto& name : without) held[shapeNamed(name)] = 1;
    for (const auto& [name, weight] : hold) {
        if (!(weight >= 0 && weight <= 1))
            throw InputError("held weight of '" + name + "' must be in [0, 1]");
        const std::size_t s = shapeNamed(name);
        held[s] = 1;
        fixed[s] = weight;
    }
    FrameSet out(frames, rig.points, 3, FrameSet::Uninitialised{});  // every frame starts as the neutral
    std::mt19937_64 rng(0x1C7FACEull ^ (static_cast<std::uint64_t>(seed) * 0x9E3779B97F4A7C15ull));
    std::uniform_real_distribution<double> threshold(0.0, 0.45), gain(1.5, 2.5);
    // Left/right pairs share a curve plus a smaller private one, as faces mostly move symmetrically.
    std::map<std::string, SmoothNoise> shared;
    struct Curve {
        const SmoothNoise* common;
        SmoothNoise own;
        double threshold, gain;
    };
    std::vector<Curve> curves;
    for (const auto& shape : rig.shapes) {
        std::string base = shape.name;
        if (base.size() > 2 && (base.ends_with("_L") || base.ends_with("_R"))) base.resize(base.size() - 2);
        auto it = shared.find(base);
        if (it == shared.end()) it = shared.emplace(base, SmoothNoise(rng, 40, 200)).first;
        curves.push_back({&it->second, SmoothNoise(rng, 40, 200), threshold(rng), gain(rng)});
    }
    const SmoothNoise jawCurve(rng, 30, 120);
    for (Index f = 0; f < frames; ++f) {
        const double t = static_cast<double>(f);
        Eigen::Map<Eigen::VectorXd> x(out.frame(f), 3 * rig.points);
        x = rig.neutral;
        for (std::size_t s = 0; s < rig.shapes.size(); ++s) {
            const Curve& c = curves[s];
            const double signal = 0.75 * (*c.common)(t) + 0.25 * c.own(t);
            const double w = held[s] ? fixed[s] : std::clamp(c.gain * (signal - c.threshold), 0.0, 1.0);
            if (w == 0) continue;
            const auto& shape = rig.shapes[s];
            for (std::size_t i = 0; i < shape.vertices.size(); ++i)
                x.segment<3>(3 * shape.vertices[i]) += w * shape.deltas[i];
        }
        const double jaw = std::clamp(1.6 * jawCurve(t) + 0.2, 0.0, 1.0);
        if (jaw == 0) continue;
        for (std::size_t i = 0; i < rig.jawVertices.size(); ++i) {
            const Index p = rig.jawVertices[i];
            const double angle = jaw * rig.jawAngle * rig.jawWeights[i];
            const double y = x[3 * p + 1] - rig.jawPivotYZ[0], z = x[3 * p + 2] - rig.jawPivotYZ[1];
            x[3 * p + 1] = rig.jawPivotYZ[0] + std::cos(angle) * y - std::sin(angle) * z;
            x[3 * p + 2] = rig.jawPivotYZ[1] + std::sin(angle) * y + std::cos(angle) * z;
        }
    }
    return out;
}

FrameSet poseIctSegments(const IctRig& rig, Index framesPerSegment, unsigned seed,
                         const std::vector<std::string>& without,
                         const std::vector<std::vector<std::pair<std::string, double>>>& holds) {
    if (holds.empty()) throw InputError("no segments to pose");
    FrameSet out(framesPerSegment * static_cast<Index>(holds.size()), rig.points, 3,
                 FrameSet::Uninitialised{});
    for (std::size_t h = 0; h < holds.size(); ++h) {
        const FrameSet segment = poseIctFrames(rig, framesPerSegment, seed, without, holds[h]);
        std::copy(segment.values.begin(), segment.values.end(),
                  out.values.begin() + static_cast<std::ptrdiff_t>(h * segment.values.size()));
    }
    return out;
}

}  // namespace pmsc::synthetic
